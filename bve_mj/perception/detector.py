"""The tomato detector: colour segmentation → the ripe blobs' outlines → the fruit in them
→ a cone fit to the target's own silhouette → a 3-D measurement of its centre with
covariance.

Why a cone and not an image circle: the rays that graze a sphere form a circular cone
around the direction to its centre, with half-angle α = asin(r/ρ). Every boundary ray b
satisfies a·b = cos α, i.e. w·b = 1 with w = a / cos α: a linear least-squares problem in w.
It is exact off-axis, where the image outline is an ellipse, and it uses only the visible
boundary, so a leaf over part of the fruit removes points instead of biasing the answer:
boundary points that lie well inside the fitted cone (occluder edges) are trimmed and the
fit repeated. Range is exact: ρ = r / sin α, r the radius the estimator assumes.

Touching fruit: the tomatoes of a truss touch, so a ripe blob is usually several fruit, and
a fruit of uneven colour (or with a stem across it) several blobs. The outlines of the blob
the prediction falls on and of the blobs around it are cut into arcs at their corners and
grouped into fruit, one circle each (:mod:`bve_mj.perception.instances`); the target is the
fruit the estimate means (given its mean and covariance: least 3-D Mahalanobis distance, and
"ambiguous" when another is about as likely; else the circle nearest the predicted
projection), and only its own outer arcs are fitted: where it meets a neighbour there is no
outline (red on red) and the blended points at the junction are left out, and the arcs of
its fragments are fitted together (those on their common convex hull). The fit is then
checked: enough of the outline seen, a circle that fits it, none of its points well outside,
a centre the arcs pin down, a radius no speck has, and (when the caller knows the predicted
range) an apparent size the prior allows.
A target that fails says why, in a :class:`NoDetection`: a merged blob is never
measured as one fruit. Where the caller gives the world's vertical, the cone is refined into
a spheroid with that axis (:mod:`bve_mj.perception.spheroid`): a tomato is flatter or taller
than wide, and a circle through its equator misplaces its centre. What passes has a
covariance that includes the fit's own uncertainty. That measurement of the chosen fruit
(fit, checks, covariance) is :func:`bve_mj.perception.outline_fit.measure_outline`, which
:func:`bve_mj.perception.all_fruit.detect_all` applies to every ripe fruit in the image.

Frames: the paper's camera frame (x optical axis, y left, z up); pixels u right, v down."""

from __future__ import annotations

import numpy as np

from bve_mj.config import DetectorConfig, FruitPrior, MeasurementConfig
from bve_mj.perception.association import (
    _associate,
    _blobs,
    _choose_blob,
    _in_window,
    _nearby,
    _shifted,
)
from bve_mj.perception.detection import Detection, Intrinsics, NoDetection, Prediction
from bve_mj.perception.instances import Arc, fruit_stretch, group_arcs, outline_arcs
from bve_mj.perception.masks import _check_image, ripe_mask
from bve_mj.perception.outline_fit import measurable_fruit, measure_outline
from bve_mj.perception.rims import interior_arcs, interior_edges

__all__ = ["detect"]


def detect(
    image_rgb: np.ndarray,
    intrinsics: Intrinsics,
    fruit: FruitPrior,
    measurement: MeasurementConfig,
    config: DetectorConfig | None = None,
    predicted_px: np.ndarray | None = None,
    *,
    expected_radius_px: float | None = None,
    prediction: Prediction | None = None,
    up_camera: np.ndarray | None = None,
) -> Detection | NoDetection:
    """Measure the target tomato in an RGB image.

    Args:
        predicted_px: where the estimate projects; the fruit (of those found in the ripe
            blob it falls on, else the blob nearest to it, and the fragments around) whose
            circle centre is nearest to it is the target. None: the fruit with the longest
            outline in the largest blob.
        expected_radius_px: the apparent radius the estimate predicts (f·tan asin(r/ρ) at
            the predicted range), if known: a fit off by more than ``size_tolerance_rel`` is
            refused (a fragment, a merged blob, a neighbour).
        prediction: the estimate in the camera frame, with its covariance (replaces
            ``predicted_px``): the fruit around its projection (within its 3σ spread) are
            candidates, the one nearest in 3-D Mahalanobis distance is the target, and when
            another is about as likely (likelihood ratio below ``ambiguity_ratio``, and
            allowed by the estimate) there is no detection: ``ambiguous``.
        up_camera: the world's vertical in the camera frame (unit, (3,)), if known: the
            fruit is fitted as a spheroid with that axis (its centre unbiased for a fruit
            that is flatter or taller than wide), else as a sphere.
    Returns:
        a :class:`Detection`, or a :class:`NoDetection` saying why (never raises on bad
        images: a wrong shape or dtype is a reason too).
    """
    cfg = config or DetectorConfig()
    problem = _check_image(image_rgb)
    if problem is not None:
        return NoDetection(problem)
    if (intrinsics.height_px, intrinsics.width_px) != image_rgb.shape[:2]:
        return NoDetection(f"image {image_rgb.shape[1]}x{image_rgb.shape[0]} does not match the intrinsics")
    predicted = None
    if predicted_px is not None:
        predicted = np.asarray(predicted_px, dtype=float).reshape(-1)
        if predicted.shape != (2,) or not np.all(np.isfinite(predicted)):
            predicted = None
    f = intrinsics.focal_px
    H, W = image_rgb.shape[:2]
    window_px = 0.0
    x0, y0, x1, y1 = 0, 0, W, H  # the part of the image looked at
    if prediction is not None:
        m = np.asarray(prediction.p_camera, dtype=float)
        if m.shape != (3,) or not np.all(np.isfinite(m)) or m[0] <= 1e-3:
            prediction = None  # behind the camera: the prediction cannot pick a fruit
        else:
            predicted = intrinsics.project(m)
            spread = float(np.sqrt(max(np.linalg.eigvalsh(prediction.cov_camera)[-1], 0.0)))
            window_px = min(f * (3.0 * spread + fruit.radius_m * 1.2) / m[0] + 4.0, float(max(H, W)))
            # the fruit the estimate allows and their neighbours lie within the window and two
            # and a half radii around it: only that part of the image is segmented
            half = window_px + 2.5 * f * fruit.radius_m * (1.0 + fruit.size_spread_rel * 3.0) / m[0] + 8.0
            if np.all(np.isfinite(predicted)):
                x0, y0 = max(int(predicted[0] - half), 0), max(int(predicted[1] - half), 0)
                x1, y1 = min(int(predicted[0] + half) + 1, W), min(int(predicted[1] + half) + 1, H)
                if x1 - x0 < 8 or y1 - y0 < 8:  # the window lies outside the image
                    x0, y0, x1, y1 = 0, 0, W, H
    mask = ripe_mask(image_rgb[y0:y1, x0:x1], cfg)
    every = [_shifted(b, x0, y0) for b in _blobs(mask)]
    blobs = [b for b in every if b.area >= cfg.min_area_px]
    if not blobs:
        what = "red" if cfg.ripe_class in (None, "red") else f"ripe ({cfg.ripe_class} or riper)"
        small = f"{what} blobs smaller than {cfg.min_area_px} px"
        return NoDetection(f"no {what} blob" if not every else small)
    target = _choose_blob(blobs, predicted)
    # ---- the fruit in and around that blob (and, with a prediction, in and around every
    # blob within its spread), each with its own outer arcs
    arcs: list[Arc] = []
    near = _nearby(every, target)
    if prediction is not None and predicted is not None:
        seen_ids = {id(b) for b in near}
        for b in _in_window(blobs, predicted, window_px):
            for n in _nearby(every, b, limit=6):
                if id(n) not in seen_ids and len(near) < 32:
                    near.append(n)
                    seen_ids.add(id(n))
    for k, b in enumerate(near):
        o = b.outline
        usable = (o[:, 0] > x0) & (o[:, 0] < x1 - 1) & (o[:, 1] > y0) & (o[:, 1] < y1 - 1)
        arcs += outline_arcs(o + 0.5, usable, k, corner_px=cfg.corner_px, margin=cfg.junction_margin)
    if cfg.interior_edge > 0.0:  # rims over a ripe neighbour: edges inside the mask
        chains = interior_edges(image_rgb[y0:y1, x0:x1], mask, cfg.interior_edge)
        arcs += interior_arcs([c + (x0, y0) for c in chains], [b.outline for b in near])
    # a fruit that is not a sphere is not a circle in the image: its outline lies inside
    # the circle through its widest parts by up to the prior's shape spread (apparent
    # radius ±s); the arcs inside by that much are still its own, count as seen, and the
    # fit's own uncertainty may be larger by a share of it. Where the vertical is known the
    # arcs are grouped with the fruit's mean shape undone (an ellipse made a circle)
    shape = fruit.shape_spread_rel
    up = up_camera if cfg.shape_grouping else None
    stretch = fruit_stretch(intrinsics, up, fruit.shape_index, target.centroid)
    found = group_arcs(arcs, tol_px=cfg.arc_tol_px, shape_rel=shape, stretch=stretch)
    if not found:
        return NoDetection("no stretch of the ripe blob's outline is a circle arc (no fruit silhouette)")
    # a fruit that shows enough of its outline can be measured; one that shows less is
    # still a fruit, unless its arcs lie inside a measurable one's circle (they are the
    # edges of a stem or calyx over it)
    whole, part = measurable_fruit(found, cfg.min_arc_deg)
    if prediction is not None:
        pick = _associate(whole + part, prediction, intrinsics, fruit, cfg)
        if isinstance(pick, NoDetection):
            return pick
        chosen, seen = pick
    elif predicted is not None:
        chosen, seen = min(whole + part, key=lambda e: float(np.linalg.norm(e[0].circle.centre - predicted)))
    else:
        own = [e for e in whole if 0 in e[0].blobs] or whole or part
        chosen, seen = max(own, key=lambda e: len(e[0].points))
    return measure_outline(
        chosen,
        seen,
        near,
        mask,
        (x0, y0),
        intrinsics,
        fruit,
        measurement,
        cfg,
        up_camera=up_camera,
        expected_radius_px=expected_radius_px,
    )
