"""Fitting the target's silhouette from its visible outline: the cone (sphere) fit with
trimming of occluded arcs, the spheroid refinement, and the fit's own uncertainty."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from bve_mj.config import DetectorConfig, FruitPrior
from bve_mj.perception.detection import Intrinsics
from bve_mj.perception.spheroid import SpheroidFit, fit_spheroid, grazing_residuals

__all__: list[str] = []  # used by the other modules of this package only


def _fit_cone(rays: np.ndarray) -> tuple[np.ndarray, float]:
    w, *_ = np.linalg.lstsq(rays, np.ones(len(rays)), rcond=None)
    n = float(np.linalg.norm(w))
    return w / n, 1.0 / n  # axis, cos α


def _trim_corners(keep: np.ndarray, margin: int) -> np.ndarray:
    """Also drop ``margin`` contour neighbours on each side of every trimmed run: where the
    silhouette meets an occluder, the last few points are blended with it."""
    cut = ~keep
    if not cut.any() or cut.all():
        return keep
    padded = np.concatenate([cut[-margin:], cut, cut[:margin]]).astype(int)
    return ~(np.convolve(padded, np.ones(2 * margin + 1, dtype=int), mode="valid") > 0)


@dataclass(frozen=True)
class _Fit:
    axis: np.ndarray  # cone axis, unit (3,)
    alpha: float  # half-angle [rad]
    centre: np.ndarray  # image of the axis [px]
    keep: np.ndarray  # points kept, (N,) bool
    resid_px: np.ndarray  # inside-positive residuals of all points [px], (N,)
    rays: np.ndarray  # the points' rays, (N, 3)


def _fit_silhouette(
    uv: np.ndarray, centre: np.ndarray, intrinsics: Intrinsics, cfg: DetectorConfig
) -> _Fit | str:
    """The cone through silhouette points ``uv`` (N, 2) [px, continuous], trimming points well
    inside it (occluder edges; for a fruit that is not a sphere, the narrower parts of its
    outline too: the fit goes through its widest parts, the equator of a flattened fruit)
    with their contour neighbours; a reason string on failure."""
    keep = np.ones(len(uv), dtype=bool)
    threshold = cfg.outlier_px
    f = intrinsics.focal_px
    for _ in range(8):
        # the silhouette runs half a pixel outside the centres of the boundary pixels
        d = uv - centre
        edge = uv + 0.5 * d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-9)
        rays = intrinsics.rays(edge)
        axis, cos_a = _fit_cone(rays[keep])
        if not (0.0 < cos_a < 1.0) or axis[0] <= 0.0:
            return "silhouette fit failed (degenerate boundary)"
        centre = intrinsics.project(axis)
        # residual in pixels: positive = inside the cone (occluder edges, calyx); only
        # inside points can be occlusion, so only they are trimmed, against a threshold
        # that tightens to 3 robust σ of the points kept (never below 0.5 px)
        alpha = math.acos(cos_a)
        ang = np.arccos(np.clip(rays @ axis, -1.0, 1.0))
        resid_px = (alpha - ang) * f
        kept = resid_px[keep]
        sigma = 1.4826 * float(np.median(np.abs(kept - np.median(kept))))
        threshold = min(threshold, max(0.5, 3.0 * sigma)) if keep.sum() < len(keep) else threshold
        # points far outside the cone cannot be its silhouette either: a neighbour's outline
        # beyond a junction that no corner marked
        far_out = resid_px < -max(2.0 * cfg.outlier_px, 4.0 * sigma)
        new_keep = _trim_corners((resid_px < threshold) & ~far_out, margin=3)
        if new_keep.sum() < cfg.min_boundary_points or np.array_equal(new_keep, keep):
            break
        keep = new_keep
    return _Fit(axis, alpha, centre, keep, resid_px, rays)


def _refine_spheroid(
    fit: _Fit, up: np.ndarray, fruit: FruitPrior, cfg: DetectorConfig, f: float, shape_px: float
) -> SpheroidFit | None:
    """The spheroid (axis near ``up``, leaning as the fruit's prior allows:
    ``FruitPrior.tilt_sigma_deg``) through the outline the circle fit saw, trimmed again by its
    own residuals: the top and bottom of a flattened fruit, which lie inside the circle
    through its equator, are its outline again, not occluder edges. None when it fails, or
    strays from the circle by more than half the apparent radius (another fruit's outline) or
    by more in size than the shape allows; a smaller stray is measured, its centre's σ bounded
    by :func:`_disagreement_px`."""
    n_up = float(np.linalg.norm(up))
    if not (np.all(np.isfinite(up)) and n_up > 1e-9):
        return None
    up = up / n_up
    resid = fit.resid_px
    use = (resid < cfg.outlier_px + shape_px) & (resid > -2.0 * cfg.outlier_px)
    prior_log = max(fruit.shape_spread_rel, 0.05)
    sph = None
    for _ in range(2):
        if use.sum() < cfg.min_boundary_points:
            return None
        sph = fit_spheroid(
            fit.rays[use], up, fit.axis, fit.alpha, fruit.shape_index, prior_log, 1.0 / f,
            fruit.tilt_sigma_rad,
        )  # fmt: skip
        if sph is None:
            return None
        r_all = f * grazing_residuals(sph.p, sph.shape_index, sph.up, fit.rays)
        new_use = _trim_corners((r_all < cfg.outlier_px) & (r_all > -2.0 * cfg.outlier_px), margin=3)
        if np.array_equal(new_use, use):
            break
        use = new_use
    if sph is None:
        return None
    object.__setattr__(sph, "resid_rad", r_all / f)  # of every outline point, for the checks
    if _moved_px(sph, fit, f) > max(shape_px + 2.0, 0.5 * f * math.tan(fit.alpha)) or (
        abs(sph.alpha / fit.alpha - 1.0) > 2.0 * fruit.shape_spread_rel + 0.05
    ):
        return None
    return sph


def _moved_px(sph: SpheroidFit, fit: _Fit, f: float) -> float:
    """How far the spheroid's centre lies from the circle fit's [px]."""
    return float(np.linalg.norm(f * (sph.axis - fit.axis)))


def _disagreement_px(sph: SpheroidFit, fit: _Fit, f: float, shape_px: float) -> float:
    """How much farther the spheroid's centre lies from the circle's than the fruit's shape
    explains (``shape_px``, and 2 px of the two fits' own play) [px]; 0 where they agree.

    The two fits trim the outline each by its own residuals, and where a neighbour's arc or a
    shaded side pulls the circle, the spheroid lands pixels from it: on ``ripe_truss``
    every-fruit episodes (seed 2468), 47 of the 66 views refused "no spheroid fits" when every
    such stray was refused were strays: the spheroid 9.3 px from the circle at the median where
    the shape allowed 7.3, its centre nearer the truth in 94% of them (0.03 of the apparent
    radius off at the median, the circle 0.22). The spheroid is measured, and the
    disagreement bounds its centre's error: in the other 6% it is the spheroid that is off."""
    return max(_moved_px(sph, fit, f) - (shape_px + 2.0), 0.0)


def _arc_deg(uv: np.ndarray, centre: np.ndarray) -> float:
    """Degrees of a circle's outline that points (N, 2) cover, in 10° sectors."""
    ang = np.degrees(np.arctan2(uv[:, 1] - centre[1], uv[:, 0] - centre[0]))
    return 10.0 * len(np.unique(np.floor((ang + 180.0) / 10.0).astype(int) % 36))


def _fit_sigmas(fit: _Fit, uv: np.ndarray, f: float) -> tuple[float, float]:
    """The fit's own 1σ of the cone axis (lateral, the worse direction) and of α [rad].

    Least squares in w: the residual of a ray is b·w - 1 ≈ tan α · (its angular residual).
    The point error is the fit's rms (at least half a pixel), and boundary errors are
    correlated along the outline (shading, blending, a ragged edge), so the points count as
    one per 10° sector they cover: a short arc pins the centre and the radius down poorly,
    and says so."""
    keep = fit.keep
    rays = fit.rays[keep]
    if len(rays) < 4:
        return math.inf, math.inf
    resid = fit.resid_px[keep] / f
    var = math.tan(fit.alpha) ** 2 * max(float(resid @ resid) / len(resid), (0.5 / f) ** 2)
    sectors = _arc_deg(uv[keep], fit.centre) / 10.0
    try:
        cov_w = var * len(rays) / max(sectors, 1.0) * np.linalg.inv(rays.T @ rays)
    except np.linalg.LinAlgError:
        return math.inf, math.inf
    nw = 1.0 / math.cos(fit.alpha)  # |w|
    g = fit.axis / (nw**2 * math.sin(fit.alpha))  # dα/dw = w / (|w|³ sin α)
    sigma_alpha = math.sqrt(max(float(g @ cov_w @ g), 0.0))
    P = (np.eye(3) - np.outer(fit.axis, fit.axis)) / nw  # da/dw
    lateral = np.linalg.eigvalsh(P @ cov_w @ P.T)
    return math.sqrt(max(float(lateral[-1]), 0.0)), sigma_alpha


def _arc_jackknife(
    rays: np.ndarray, keep: np.ndarray, arc_of: np.ndarray, min_points: int
) -> tuple[float, float]:
    """Jackknife over the outline's arcs: the cone refitted without each arc in turn (where
    the rest still has ``min_points``), 1σ of the axis across it (the worse direction) and of
    α [rad] from the replicates' deviations from the cone through every kept point, scaled
    by (n - 1)/n for n arcs. Zero for a single arc (nothing to compare). The reference is
    that cone, not the spheroid the detector reports: for a flattened fruit the two differ
    by a few pixels, which is the spheroid's correction, not a disagreement of the arcs."""
    labels = np.unique(arc_of[keep])
    n = len(labels)
    if n < 2:
        return 0.0, 0.0
    axis, cos_a = _fit_cone(rays[keep])
    if not 0.0 < cos_a < 1.0:
        return 0.0, 0.0
    alpha = math.acos(cos_a)
    C, var_alpha = np.zeros((3, 3)), 0.0
    for j in labels:
        rest = keep & (arc_of != j)
        if rest.sum() < min_points:
            continue
        a_j, cos_j = _fit_cone(rays[rest])
        if not (0.0 < cos_j < 1.0) or a_j[0] <= 0.0:
            continue
        d = a_j - axis
        C += np.outer(d, d)
        var_alpha += (math.acos(cos_j) - alpha) ** 2
    k = (n - 1) / n
    return math.sqrt(k * float(np.linalg.eigvalsh(C)[-1])), math.sqrt(k * var_alpha)
