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

Frames: the paper's camera frame (x optical axis, y left, z up); pixels u right, v down.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from bve_mj.config import CameraConfig, DetectorConfig, FruitPrior, MeasurementConfig
from bve_mj.geometry import pixel_rays, project_point, ray_frame
from bve_mj.perception.instances import Arc, Circle, FruitOutline, group_arcs, hull_points, outline_arcs
from bve_mj.perception.spheroid import SpheroidFit, fit_spheroid, grazing_residuals

__all__ = ["Detection", "Intrinsics", "NoDetection", "Prediction", "detect", "red_mask", "ripe_mask"]

_OPEN_KERNEL = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5))
_CHI2_3_999 = 16.266  # χ²(3) quantile at 0.999: a candidate the estimate allows


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics the detector assumes (square pixels) [px]."""

    focal_px: float
    width_px: int
    height_px: int
    cx_offset_px: float = 0.0
    cy_offset_px: float = 0.0

    @classmethod
    def from_camera(cls, camera: CameraConfig) -> Intrinsics:
        return cls(camera.focal_px, camera.width_px, camera.height_px)

    def rays(self, uv: np.ndarray) -> np.ndarray:
        offset = np.array([self.cx_offset_px, self.cy_offset_px])
        shifted = np.atleast_2d(np.asarray(uv, dtype=float)) - offset
        return pixel_rays(shifted, self.focal_px, self.width_px, self.height_px)

    def project(self, p_camera: np.ndarray) -> np.ndarray:
        uv = project_point(p_camera, self.focal_px, self.width_px, self.height_px)
        return uv + np.array([self.cx_offset_px, self.cy_offset_px])


@dataclass(frozen=True)
class Detection:
    """A measured tomato.

    Attributes:
        centre_px: image of the fitted cone axis (u, v) [px].
        radius_px: apparent radius f·tan α [px].
        bearing_camera: unit direction to the fruit centre in the camera frame, (3,).
        angular_radius_rad: α.
        range_m: ρ = r / sin α with the assumed radius.
        p_camera: fruit centre in the camera frame [m], (3,): the measurement z.
        cov_camera: its covariance [m²], (3, 3): range σ along the bearing, lateral σ across.
        area_px: blob area; boundary_points: silhouette points used in the fit;
        trimmed_fraction: share of boundary points rejected as occluder or image edges.
        arc_deg: how much of the fruit's outline the fit saw (10° sectors around its centre).
        centre_fit_px, radius_fit_px: the fit's own 1σ of the centre (across the bearing, the
            worse direction) and of the apparent radius, from its residuals and how much
            outline it saw [px, as f·angle].
        centre_jackknife_px, radius_jackknife_px: the spread of the fits that leave one arc
            of the outline out (0 for a single arc) [px, as f·angle].
    The noise model (:mod:`bve_mj.estimation.noise`) turns these into the measurement's σ.
    """

    centre_px: np.ndarray
    radius_px: float
    bearing_camera: np.ndarray
    angular_radius_rad: float
    range_m: float
    p_camera: np.ndarray
    cov_camera: np.ndarray
    area_px: int
    boundary_points: int
    trimmed_fraction: float
    arc_deg: float = 360.0
    centre_fit_px: float = 0.0
    radius_fit_px: float = 0.0
    centre_jackknife_px: float = 0.0
    radius_jackknife_px: float = 0.0


@dataclass(frozen=True)
class NoDetection:
    """Nothing measured, and why (``ambiguous``: more than one fruit fits the estimate)."""

    reason: str

    @property
    def ambiguous(self) -> bool:
        return self.reason.startswith("ambiguous")


@dataclass(frozen=True)
class Prediction:
    """Where the estimate puts the target, in the camera frame (x optical axis, y left, z up):
    N(p_camera, cov_camera) [m]. It picks the target among the fruit in view by Mahalanobis
    distance in 3-D (bearing and size-based range), not by pixel distance: a neighbour
    nearer in the image but at the wrong range, or outside the estimate's spread, loses."""

    p_camera: np.ndarray
    cov_camera: np.ndarray


def ripe_mask(image_rgb: np.ndarray, cfg: DetectorConfig) -> np.ndarray:
    """Pixels of ripe hue (``cfg.ripe_hue_max``: red, or up to the ripeness class the
    settings accept; red wraps around hue 180), saturated and lit enough, and the skin of
    those fruit that a highlight or uneven colour turns orange (hue up to
    ``cfg.extend_hue_max``, in a region that touches ripe pixels): uint8 mask 0/255."""
    hsv = cv2.cvtColor(image_rgb, cv2.COLOR_RGB2HSV)
    low = (cfg.min_saturation, cfg.min_value)
    wrap = cv2.inRange(hsv, (cfg.red_hue_min_wrap, *low), (255, 255, 255))
    ripe = cv2.bitwise_or(cv2.inRange(hsv, (0, *low), (cfg.ripe_hue_max, 255, 255)), wrap)
    if cfg.extend_hue_max <= cfg.ripe_hue_max:
        return ripe
    skin = cv2.bitwise_or(cv2.inRange(hsv, (0, *low), (cfg.extend_hue_max, 255, 255)), wrap)
    # only patches: the rim where red blends into green leaves is orange too, a pixel or
    # two wide; opening removes it (and any other sliver) before the patches join the red
    patch = cv2.morphologyEx(cv2.bitwise_and(skin, cv2.bitwise_not(ripe)), cv2.MORPH_OPEN, _OPEN_KERNEL)
    skin = cv2.bitwise_or(ripe, patch)
    n, labels = cv2.connectedComponents(skin, connectivity=8)
    touching = np.zeros(n, dtype=bool)
    touching[np.unique(labels[ripe > 0])] = True
    touching[0] = False
    return np.where(touching[labels], 255, 0).astype(np.uint8)


red_mask = ripe_mask
"""The former name of :func:`ripe_mask`."""


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


def _check_image(image: object) -> str | None:
    if not isinstance(image, np.ndarray):
        return f"image is a {type(image).__name__}, not a numpy array"
    if image.ndim != 3 or image.shape[2] != 3 or image.shape[0] < 8 or image.shape[1] < 8:
        return f"image shape {image.shape} is not (H >= 8, W >= 8, 3)"
    if image.dtype != np.uint8:
        return f"image dtype {image.dtype} is not uint8"
    return None


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
    """The spheroid (axis ``up``) through the outline the circle fit saw, trimmed again by its
    own residuals: the top and bottom of a flattened fruit, which lie inside the circle
    through its equator, are its outline again, not occluder edges. None (keep the circle)
    when it fails or strays from the circle by more than the shape allows."""
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
        sph = fit_spheroid(fit.rays[use], up, fit.axis, fit.alpha, fruit.shape_index, prior_log, 1.0 / f)
        if sph is None:
            return None
        r_all = f * grazing_residuals(sph.p, sph.shape_index, up, fit.rays)
        new_use = _trim_corners((r_all < cfg.outlier_px) & (r_all > -2.0 * cfg.outlier_px), margin=3)
        if np.array_equal(new_use, use):
            break
        use = new_use
    if sph is None:
        return None
    object.__setattr__(sph, "resid_rad", r_all / f)  # of every outline point, for the checks
    moved_px = float(np.linalg.norm(f * (sph.axis - fit.axis)))
    if moved_px > shape_px + 2.0 or abs(sph.alpha / fit.alpha - 1.0) > 2.0 * fruit.shape_spread_rel + 0.05:
        return None
    return sph


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


@dataclass(frozen=True)
class _Blob:
    """A connected ripe region: its outer outline (N, 2) in pixel indices, its area (pixels,
    from the outline), its box (x, y, w, h) and centroid [px, continuous]."""

    outline: np.ndarray
    area: float
    box: tuple[int, int, int, int]
    centroid: np.ndarray


def _blobs(mask: np.ndarray) -> list[_Blob]:
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    out = []
    for c in contours:
        m = cv2.moments(c)
        pts = c[:, 0, :].astype(float)
        centroid = np.array([m["m10"] / m["m00"], m["m01"] / m["m00"]]) if m["m00"] > 0 else pts.mean(axis=0)
        # pixels = the polygon through the boundary pixels' centres + half a pixel around it
        area = float(m["m00"]) + 0.5 * cv2.arcLength(c, True) + 1.0
        x, y, w, h = cv2.boundingRect(c)
        out.append(_Blob(pts, area, (x, y, w, h), centroid + 0.5))
    return out


def _shifted(blob: _Blob, dx: int, dy: int) -> _Blob:
    """``blob`` of a crop whose corner is (dx, dy), in the whole image's pixels."""
    if dx == 0 and dy == 0:
        return blob
    x, y, w, h = blob.box
    d = np.array([dx, dy], dtype=float)
    return _Blob(blob.outline + d, blob.area, (x + dx, y + dy, w, h), blob.centroid + d)


def _inside(fruit: FruitOutline, circle: Circle) -> bool:
    """Whether most of a fruit's outline points lie within another's circle."""
    d = np.hypot(fruit.points[:, 0] - circle.centre[0], fruit.points[:, 1] - circle.centre[1])
    return float(np.mean(d <= circle.radius + 2.0)) >= 0.8


def _choose_blob(blobs: list[_Blob], predicted: np.ndarray | None) -> _Blob:
    if predicted is None:
        return max(blobs, key=lambda b: b.area)
    at = (float(predicted[0] - 0.5), float(predicted[1] - 0.5))
    for b in blobs:
        x, y, w, h = b.box
        inside_box = x <= at[0] <= x + w and y <= at[1] <= y + h
        if inside_box and cv2.pointPolygonTest(b.outline.astype(np.float32), at, False) >= 0:
            return b  # the blob the prediction falls on
    return min(blobs, key=lambda b: float(np.linalg.norm(b.centroid - predicted)))


def _nearby(blobs: list[_Blob], target: _Blob, limit: int = 12) -> list[_Blob]:
    """The target blob and the blobs whose boxes overlap its box grown by half its size:
    the other fragments a fruit of that blob could be in (largest first, at most ``limit``)."""
    x, y, w, h = target.box
    gx, gy = w // 2 + 2, h // 2 + 2
    near = [
        b
        for b in blobs
        if b is not target
        and b.area >= 4
        and b.box[0] < x + w + gx
        and b.box[0] + b.box[2] > x - gx
        and b.box[1] < y + h + gy
        and b.box[1] + b.box[3] > y - gy
    ]
    near.sort(key=lambda b: -b.area)
    return [target, *near[:limit]]


def _in_window(blobs: list[_Blob], centre: np.ndarray, half_px: float) -> list[_Blob]:
    """The blobs whose boxes meet the square of half-width ``half_px`` around ``centre``."""
    x0, y0 = centre - half_px
    x1, y1 = centre + half_px
    return [
        b
        for b in blobs
        if b.box[0] <= x1 and b.box[0] + b.box[2] >= x0 and b.box[1] <= y1 and b.box[1] + b.box[3] >= y0
    ]


def _rough_measurement(
    circle: Circle, intrinsics: Intrinsics, fruit: FruitPrior
) -> tuple[np.ndarray, np.ndarray] | None:
    """A fruit's centre in the camera frame from its grouped circle alone, with a generous
    covariance (a sixth of the radius in the centre, 15% in the apparent size, the prior's
    size spread): enough to tell which fruit the estimate means. None for a degenerate one."""
    f = intrinsics.focal_px
    ray = intrinsics.rays(circle.centre)[0]
    alpha = math.atan(circle.radius / f)
    if not (0.0 < alpha < 1.5) or ray[0] <= 0.0:
        return None
    rho = fruit.radius_m / math.sin(alpha)
    sigma_lat = rho * max(2.0, circle.radius / 6.0) / f
    sigma_rho = rho * math.hypot(fruit.size_spread_rel, 0.15)
    return rho * ray, _along_across(ray, sigma_rho, sigma_lat)


def _along_across(axis: np.ndarray, sigma_along: float, sigma_across: float) -> np.ndarray:
    """Covariance with σ ``sigma_along`` along the unit ``axis`` and ``sigma_across`` across."""
    U = ray_frame(axis)
    cov = U @ np.diag([sigma_along**2, sigma_across**2, sigma_across**2]) @ U.T
    return 0.5 * (cov + cov.T)


def _area_inside(mask: np.ndarray, centre: np.ndarray, radius: float) -> int:
    """Ripe pixels within the fitted circle (plus a pixel): the fruit's visible area."""
    H, W = mask.shape
    r = radius + 1.0
    x0, x1 = max(math.floor(centre[0] - r), 0), min(math.ceil(centre[0] + r), W)
    y0, y1 = max(math.floor(centre[1] - r), 0), min(math.ceil(centre[1] + r), H)
    if x1 <= x0 or y1 <= y0:
        return 0
    yy, xx = np.ogrid[y0:y1, x0:x1]
    inside = (xx + 0.5 - centre[0]) ** 2 + (yy + 0.5 - centre[1]) ** 2 <= r * r
    return int(np.count_nonzero(inside & (mask[y0:y1, x0:x1] > 0)))


def _associate(
    fruits: list[tuple[FruitOutline, float]],
    prediction: Prediction,
    intrinsics: Intrinsics,
    fruit: FruitPrior,
    cfg: DetectorConfig,
) -> tuple[FruitOutline, float] | NoDetection:
    """The fruit the prediction means: least Mahalanobis distance between its rough 3-D
    centre and the prediction; ambiguous when another fruit (not the same one seen twice:
    circles apart by more than half a radius) is allowed by the prediction and about as
    likely."""
    scored = []
    for fr, seen in fruits:
        rough = _rough_measurement(fr.circle, intrinsics, fruit)
        if rough is None:
            continue
        z, R = rough
        nu = z - prediction.p_camera
        d2 = float(nu @ np.linalg.solve(prediction.cov_camera + R, nu))
        scored.append((d2, fr, seen))
    if not scored:
        return NoDetection("no fruit silhouette in the ripe blobs near the estimate")
    scored.sort(key=lambda e: e[0])
    d2_best, best, seen_best = scored[0]
    margin = 2.0 * math.log(cfg.ambiguity_ratio)
    for d2, other, _ in scored[1:]:
        apart = float(np.linalg.norm(other.circle.centre - best.circle.centre))
        if apart <= 0.5 * max(best.circle.radius, other.circle.radius):
            continue  # the same fruit, in two groups of arcs
        if d2 <= _CHI2_3_999 and d2 - d2_best < margin:
            return NoDetection(
                f"ambiguous: two fruit fit the estimate (Mahalanobis^2 {d2_best:.1f} and {d2:.1f}, "
                f"likelihood ratio {math.exp(0.5 * (d2 - d2_best)):.1f} < {cfg.ambiguity_ratio:g})"
            )
        break  # sorted: the rest are less likely still
    return best, seen_best


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
