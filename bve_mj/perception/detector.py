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
covariance that includes the fit's own uncertainty.

Frames: the paper's camera frame (x optical axis, y left, z up); pixels u right, v down."""

from __future__ import annotations

import math

import numpy as np

from bve_mj.config import DetectorConfig, FruitPrior, MeasurementConfig
from bve_mj.perception.association import (
    _along_across,
    _area_inside,
    _associate,
    _blobs,
    _choose_blob,
    _in_window,
    _inside,
    _nearby,
    _shifted,
)
from bve_mj.perception.detection import Detection, Intrinsics, NoDetection, Prediction
from bve_mj.perception.instances import Arc, FruitOutline, group_arcs, hull_points, outline_arcs
from bve_mj.perception.masks import _check_image, ripe_mask
from bve_mj.perception.silhouette import (
    _arc_deg,
    _arc_jackknife,
    _fit_sigmas,
    _fit_silhouette,
    _refine_spheroid,
    _trim_corners,
)

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
    # a fruit that is not a sphere is not a circle in the image: its outline lies inside
    # the circle through its widest parts by up to the prior's shape spread (apparent
    # radius ±s); the arcs inside by that much are still its own, count as seen, and the
    # fit's own uncertainty may be larger by a share of it
    shape = fruit.shape_spread_rel
    found = group_arcs(arcs, tol_px=cfg.arc_tol_px, shape_rel=shape)
    if not found:
        return NoDetection("no stretch of the ripe blob's outline is a circle arc (no fruit silhouette)")
    # a fruit that shows enough of its outline can be measured; one that shows less is
    # still a fruit, unless its arcs lie inside a measurable one's circle (they are the
    # edges of a stem or calyx over it)
    whole: list[tuple[FruitOutline, float]] = []
    part: list[tuple[FruitOutline, float]] = []
    for fr in found:
        seen = _arc_deg(fr.points, fr.circle.centre)
        (whole if seen >= cfg.min_arc_deg else part).append((fr, seen))
    part = [(fr, seen) for fr, seen in part if not any(_inside(fr, w.circle) for w, _ in whole)]
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
    if seen < cfg.min_arc_deg:
        return NoDetection(
            f"only {seen:.0f} deg of the target's outline visible (< {cfg.min_arc_deg:.0f}): "
            "hidden by its neighbours or occluders"
        )
    uv = chosen.points
    on_hull = hull_points(uv)
    uv = uv[on_hull]
    arc_of = np.concatenate([np.full(len(a.points), j) for j, a in enumerate(chosen.arcs)])[on_hull]
    if len(uv) < cfg.min_boundary_points:
        return NoDetection(f"only {len(uv)} silhouette points of the target apart from its neighbours")
    shape_px = shape * chosen.circle.radius
    fit = _fit_silhouette(uv, chosen.circle.centre, intrinsics, cfg)
    if isinstance(fit, str):
        return NoDetection(fit)
    # ---- a spheroid with the fruit's axis, where the caller knows it (the circle through a
    # flattened fruit's equator is off by the difference of its semi-axes); the checks then
    # take its residuals, and the shape no longer loosens them
    sph = None
    if up_camera is not None:
        sph = _refine_spheroid(fit, np.asarray(up_camera, dtype=float), fruit, cfg, f, shape_px)
        if sph is None:
            return NoDetection(
                "no spheroid with the fruit's axis fits the outline: a fragment or not a fruit"
            )
    if sph is not None:
        resid_px = f * sph.resid_rad
        keep = _trim_corners((resid_px < cfg.outlier_px) & (resid_px > -2.0 * cfg.outlier_px), margin=3)
        axis, alpha, centre, slack_px = sph.axis, sph.alpha, intrinsics.project(sph.axis), 0.0
    else:
        resid_px, keep = fit.resid_px, fit.keep
        axis, alpha, centre, slack_px = fit.axis, fit.alpha, fit.centre, shape_px
    # ---- is it one fruit, well seen?
    if keep.sum() < cfg.min_boundary_points:
        return NoDetection(f"only {int(keep.sum())} silhouette points left after trimming occluder edges")
    # the outline seen: the points kept, and (circle fit) those a fruit that is not a sphere
    # keeps inside the circle through its widest parts (its outline is an ellipse)
    on_outline = keep | ((resid_px > 0.0) & (resid_px < cfg.outlier_px + 0.5 * slack_px))
    arc = _arc_deg(uv[on_outline], centre)
    if arc < cfg.min_arc_deg:
        return NoDetection(f"only {arc:.0f} deg of the target's outline visible (< {cfg.min_arc_deg:.0f})")
    rms = float(np.sqrt(np.mean(resid_px[keep] ** 2)))
    if rms > cfg.max_fit_rms_px:
        return NoDetection(f"merged blob or not a fruit: its outline fits a circle to {rms:.2f} px rms")
    outside = float(np.mean(resid_px < -cfg.outlier_px))
    if outside > cfg.max_outside_share:
        return NoDetection(
            f"merged blob: {100 * outside:.0f}% of the target's outline lies outside its fitted circle"
        )
    radius_px = f * math.tan(alpha)
    if radius_px < cfg.min_radius_px:
        return NoDetection(f"a speck of colour, not a fruit: apparent radius {radius_px:.1f} px")
    if sph is not None:
        var = max(float(np.mean((resid_px[keep] / f) ** 2)), (0.5 / f) ** 2)
        sectors = _arc_deg(uv[keep], centre) / 10.0
        lat_fit, alpha_fit = sph.sigmas(
            var, max(sectors, 1.0) / len(sph.jac_rad), max(fruit.shape_spread_rel, 0.05)
        )
    else:
        lat_fit, alpha_fit = _fit_sigmas(fit, uv, f)
    # arcs grouped into one fruit may not all be its own (a neighbour's arc that happens to
    # lie near its circle) or may be off together (shading along one side): the spread of
    # the fits that leave one arc out says how far the centre can be off
    lat_jk, alpha_jk = _arc_jackknife(fit.rays, keep, arc_of, cfg.min_boundary_points)
    if lat_fit * f > cfg.max_fit_sigma_px + 0.25 * slack_px:
        return NoDetection(
            f"the visible arcs fix the target's centre only to {lat_fit * f:.1f} px (1 sigma): too little "
            "of its outline, or a ragged one"
        )
    if expected_radius_px is not None and math.isfinite(expected_radius_px) and expected_radius_px > 0:
        ratio = radius_px / expected_radius_px
        if not 1.0 / (1.0 + cfg.size_tolerance_rel) <= ratio <= 1.0 + cfg.size_tolerance_rel:
            return NoDetection(
                f"apparent radius {radius_px:.1f} px is implausible for the predicted range "
                f"(expected {expected_radius_px:.1f} px): a fragment, a merged blob or another fruit"
            )
    # the shape no longer biases the size when the spheroid measured it: only the radius does
    size_spread = fruit.size_spread_rel if sph is None else fruit.radius_spread_rel / math.sqrt(3.0)
    outline_points = sum(len(near[k].outline) for k in chosen.blobs)
    rho = fruit.radius_m / math.sin(alpha)
    # covariance: lateral from the centre pixel error; range from the unknown true radius
    # (uniform ±spread) and the pixel error of the apparent radius, dρ/dα = -ρ / tan α;
    # each with the fit's own uncertainty (a short arc), or the arcs' jackknife spread where
    # that is larger, added in quadrature
    sigma_lat = rho * math.hypot(measurement.centre_sigma_px / f, max(lat_fit, lat_jk))
    sigma_alpha = math.hypot(measurement.radius_sigma_px / f, max(alpha_fit, alpha_jk))
    sigma_rho = rho * math.hypot(size_spread, sigma_alpha / math.tan(alpha))
    cov = _along_across(axis, sigma_rho, sigma_lat)
    return Detection(
        centre_px=centre,
        radius_px=radius_px,
        bearing_camera=axis,
        angular_radius_rad=alpha,
        range_m=rho,
        p_camera=rho * axis,
        cov_camera=cov,
        area_px=_area_inside(mask, centre - np.array([x0, y0]), radius_px),
        boundary_points=int(keep.sum()),
        trimmed_fraction=1.0 - float(keep.sum()) / max(outline_points, 1),
        arc_deg=arc,
        centre_fit_px=f * lat_fit,
        radius_fit_px=f * alpha_fit,
        centre_jackknife_px=f * lat_jk,
        radius_jackknife_px=f * alpha_jk,
    )
