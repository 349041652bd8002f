"""One fruit's measurement from its grouped outline: the cone fit to its own silhouette arcs,
the spheroid refinement, the checks that refuse a poor fit, and the covariance.

Both the single-target detector (:func:`bve_mj.perception.detector.detect`) and the
every-fruit detector (:func:`bve_mj.perception.all_fruit.detect_all`) pick fruit from the ripe
mask's outline arcs (:mod:`bve_mj.perception.instances`) and hand each one here, so every fruit
is measured and checked the same way.

Frames: the paper's camera frame (x optical axis, y left, z up); pixels u right, v down."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from bve_mj.config import DetectorConfig, FruitPrior, MeasurementConfig
from bve_mj.perception.association import _along_across, _area_inside, _Blob, _inside
from bve_mj.perception.detection import Detection, Intrinsics, NoDetection
from bve_mj.perception.instances import FruitOutline, hull_points
from bve_mj.perception.silhouette import (
    _arc_deg,
    _arc_jackknife,
    _disagreement_px,
    _fit_sigmas,
    _fit_silhouette,
    _refine_spheroid,
    _trim_corners,
)

__all__ = ["measurable_fruit", "measure_outline"]


def measurable_fruit(
    found: Sequence[FruitOutline], min_arc_deg: float
) -> tuple[list[tuple[FruitOutline, float]], list[tuple[FruitOutline, float]]]:
    """The fruit grouped from a set of arcs, each with the degrees of its outline seen (10°
    sectors around its circle's centre): those that show at least ``min_arc_deg`` (can be
    measured), and those that show less but still count as fruit, i.e. whose outline does
    not lie inside a measurable one's circle (else its arcs are the edges of a stem or calyx
    over that fruit, and are dropped). Both in the order of ``found``."""
    whole: list[tuple[FruitOutline, float]] = []
    part: list[tuple[FruitOutline, float]] = []
    for fr in found:
        seen = _arc_deg(fr.points, fr.circle.centre)
        (whole if seen >= min_arc_deg else part).append((fr, seen))
    part = [(fr, seen) for fr, seen in part if not any(_inside(fr, w.circle) for w, _ in whole)]
    return whole, part


_RIM_SECTORS = 36


def _neighbour_share(mask: np.ndarray, centre: np.ndarray, radius_px: float) -> float:
    """The share of a fitted circle's rim where the ripe mask goes on just outside it (at
    r + max(2 px, 8%), in 36 directions; outside the mask counts as not ripe): a ripe
    neighbour touching or overlapping the fruit there. Red on red shows no outline, so
    the fit there rests on shading or on a neighbour's arc near the fruit's circle: the
    views that err most in a truss are those with much of the rim against a neighbour.
    ``centre`` is in the mask's own pixels (pixel centres at +0.5)."""
    rim = radius_px + max(2.0, 0.08 * radius_px)
    t = (np.arange(_RIM_SECTORS) + 0.5) * (2.0 * math.pi / _RIM_SECTORS)
    u = np.floor(centre[0] + rim * np.cos(t)).astype(int)
    v = np.floor(centre[1] + rim * np.sin(t)).astype(int)
    H, W = mask.shape
    ok = (u >= 0) & (u < W) & (v >= 0) & (v < H)
    return float(np.count_nonzero(mask[v[ok], u[ok]] > 0)) / _RIM_SECTORS


def measure_outline(
    outline: FruitOutline,
    seen_deg: float,
    blobs: Sequence[_Blob],
    mask: np.ndarray,
    mask_origin_px: tuple[int, int],
    intrinsics: Intrinsics,
    fruit: FruitPrior,
    measurement: MeasurementConfig,
    cfg: DetectorConfig,
    *,
    up_camera: np.ndarray | None = None,
    expected_radius_px: float | None = None,
) -> Detection | NoDetection:
    """Measure one fruit from its own outline arcs, or say why not.

    The arcs on their common convex hull are fitted with a cone (a sphere's silhouette),
    trimming points well inside it (occluder edges); where the world's vertical is known the
    cone is refined into a spheroid with that axis. The fit is then checked: enough of the
    outline seen, a circle that fits it (rms), none of its points well outside (a merged
    blob), a radius no speck has, a centre the arcs pin down, and (when the caller knows the
    predicted range) an apparent size the prior allows. What passes gets a covariance that
    includes the fit's own uncertainty and the spread of the fits that leave one arc out.

    Args:
        outline: the fruit, as grouped by :func:`~bve_mj.perception.instances.group_arcs`
            (its arcs' points in whole-image pixels, continuous: u right, v down).
        seen_deg: degrees of its outline the arcs cover (10° sectors around its circle).
        blobs: the blobs its arcs' ``blob`` numbers index (for the share of outline trimmed).
        mask: the ripe mask (uint8 0/255) the blobs came from, possibly a crop of the image.
        mask_origin_px: (u, v) of the mask's top-left pixel in the image [px].
        intrinsics, fruit, measurement, cfg: the camera, the fruit prior (its radius turns
            the angular radius into range), the measurement noise, the detector settings.
        up_camera: the world's vertical in the camera frame (x optical axis, y left, z up;
            unit, (3,)), if known: the fruit is fitted as a spheroid with that axis.
        expected_radius_px: the apparent radius the estimate predicts, if known: a fit off
            by more than ``cfg.size_tolerance_rel`` is refused.
    Returns:
        a :class:`Detection` (centre, radius in px; bearing, range, covariance in the camera
        frame), or a :class:`NoDetection` with the reason.
    """
    f = intrinsics.focal_px
    x0, y0 = mask_origin_px
    if seen_deg < cfg.min_arc_deg:
        return NoDetection(
            f"only {seen_deg:.0f} deg of the target's outline visible (< {cfg.min_arc_deg:.0f}): "
            "hidden by its neighbours or occluders",
            partial=True,
        )
    uv = outline.points
    on_hull = hull_points(uv)
    uv = uv[on_hull]
    arc_of = np.concatenate([np.full(len(a.points), j) for j, a in enumerate(outline.arcs)])[on_hull]
    if len(uv) < cfg.min_boundary_points:
        return NoDetection(f"only {len(uv)} silhouette points of the target apart from its neighbours")
    # a fruit that is not a sphere is not a circle in the image: its outline lies inside
    # the circle through its widest parts by up to the prior's shape spread (apparent
    # radius ±s); the fit's own uncertainty may be larger by a share of it
    shape_px = fruit.shape_spread_rel * outline.circle.radius
    fit = _fit_silhouette(uv, outline.circle.centre, intrinsics, cfg)
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
    disagreement_px = 0.0
    if sph is not None:
        resid_px = f * sph.resid_rad
        keep = _trim_corners((resid_px < cfg.outlier_px) & (resid_px > -2.0 * cfg.outlier_px), margin=3)
        axis, alpha, centre, slack_px = sph.axis, sph.alpha, intrinsics.project(sph.axis), 0.0
        disagreement_px = _disagreement_px(sph, fit, f, shape_px)
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
        return NoDetection(
            f"only {arc:.0f} deg of the target's outline visible (< {cfg.min_arc_deg:.0f})", partial=True
        )
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
            "of its outline, or a ragged one",
            partial=True,
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
    outline_points = sum(len(blobs[k].outline) for k in outline.blobs) + sum(
        len(a.points) for a in outline.arcs if a.interior
    )
    rho = fruit.radius_m / math.sin(alpha)
    # covariance: lateral from the centre pixel error; range from the unknown true radius
    # (uniform ±spread) and the pixel error of the apparent radius, dρ/dα = -ρ / tan α;
    # each with the fit's own uncertainty (a short arc), or the arcs' jackknife spread where
    # that is larger, added in quadrature
    sigma_lat = rho * math.hypot(measurement.centre_sigma_px / f, max(lat_fit, lat_jk), disagreement_px / f)
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
        neighbour_share=_neighbour_share(mask, centre - np.array([x0, y0]), radius_px),
        boundary_points=int(keep.sum()),
        trimmed_fraction=1.0 - float(keep.sum()) / max(outline_points, 1),
        arc_deg=arc,
        centre_fit_px=f * lat_fit,
        radius_fit_px=f * alpha_fit,
        centre_jackknife_px=f * lat_jk,
        radius_jackknife_px=f * alpha_jk,
        centre_disagreement_px=disagreement_px,
    )
