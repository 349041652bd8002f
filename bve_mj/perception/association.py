"""Which blob is the target: blobs of the ripe mask, the one the predicted projection points
at, neighbours nearby, and the rough measurement before the fit."""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from bve_mj.config import DetectorConfig, FruitPrior
from bve_mj.geometry import ray_frame
from bve_mj.perception.detection import _CHI2_3_999, Intrinsics, NoDetection, Prediction
from bve_mj.perception.instances import Circle, FruitOutline

__all__: list[str] = []  # used by the other modules of this package only


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
        scored.append((d2, fr, seen, (z, R)))
    if not scored:
        return NoDetection("no fruit silhouette in the ripe blobs near the estimate")
    scored.sort(key=lambda e: e[0])
    d2_best, best, seen_best, rough_best = scored[0]
    margin = 2.0 * math.log(cfg.ambiguity_ratio)
    for d2, other, _, rough in scored[1:]:
        apart = float(np.linalg.norm(other.circle.centre - best.circle.centre))
        if apart <= 0.5 * max(best.circle.radius, other.circle.radius):
            continue  # the same fruit, in two groups of arcs
        if d2 <= _CHI2_3_999 and d2 - d2_best < margin:
            return NoDetection(
                f"ambiguous: two fruit fit the estimate (Mahalanobis^2 {d2_best:.1f} and {d2:.1f}, "
                f"likelihood ratio {math.exp(0.5 * (d2 - d2_best)):.1f} < {cfg.ambiguity_ratio:g})",
                (rough_best, rough),
            )
        break  # sorted: the rest are less likely still
    return best, seen_best
