"""The tomato detector: colour segmentation → connected components → the target blob → a
cone fit to its visible silhouette → a 3-D measurement of the fruit centre with covariance.

Why a cone and not an image circle: the rays that graze a sphere form a circular cone
around the direction to its centre, with half-angle α = asin(r/ρ). Every boundary ray b
satisfies a·b = cos α, i.e. w·b = 1 with w = a / cos α: a linear least-squares problem in w.
It is exact off-axis, where the image outline is an ellipse, and it uses only the visible
boundary, so a leaf over part of the fruit removes points instead of biasing the answer:
boundary points that lie well inside the fitted cone (occluder edges) are trimmed and the
fit repeated. Range is exact: ρ = r / sin α, r the radius the estimator assumes.

Frames: the paper's camera frame (x optical axis, y left, z up); pixels u right, v down.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from bve_mj.config import CameraConfig, DetectorConfig, FruitPrior, MeasurementConfig
from bve_mj.geometry import pixel_rays, project_point

__all__ = ["Detection", "Intrinsics", "NoDetection", "detect", "red_mask"]


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


@dataclass(frozen=True)
class NoDetection:
    """Nothing measured, and why."""

    reason: str


def red_mask(image_rgb: np.ndarray, cfg: DetectorConfig) -> np.ndarray:
    """Pixels of ripe-red hue, saturated and lit enough: uint8 mask 0/255."""
    hsv = cv2.cvtColor(image_rgb, cv2.COLOR_RGB2HSV)
    h, s, v = hsv[..., 0], hsv[..., 1], hsv[..., 2]
    red = (
        ((h <= cfg.red_hue_max) | (h >= cfg.red_hue_min_wrap))
        & (s >= cfg.min_saturation)
        & (v >= cfg.min_value)
    )
    return red.astype(np.uint8) * 255


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


def detect(
    image_rgb: np.ndarray,
    intrinsics: Intrinsics,
    fruit: FruitPrior,
    measurement: MeasurementConfig,
    config: DetectorConfig | None = None,
    predicted_px: np.ndarray | None = None,
) -> Detection | NoDetection:
    """Measure the target tomato in an RGB image.

    Args:
        predicted_px: where the estimate projects; the red blob nearest to it is the target
            (the largest red blob when None).
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
    mask = red_mask(image_rgb, cfg)
    n, labels, stats, centroids = cv2.connectedComponentsWithStats(mask, connectivity=8)
    blobs = [i for i in range(1, n) if stats[i, cv2.CC_STAT_AREA] >= cfg.min_area_px]
    if not blobs:
        return NoDetection("no red blob" if n <= 1 else f"red blobs smaller than {cfg.min_area_px} px")
    if predicted_px is not None and np.all(np.isfinite(predicted_px)):
        target = min(blobs, key=lambda i: float(np.linalg.norm(centroids[i] + 0.5 - predicted_px)))
    else:
        target = max(blobs, key=lambda i: int(stats[i, cv2.CC_STAT_AREA]))
    blob = (labels == target).astype(np.uint8)
    contours, _ = cv2.findContours(blob, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    pts = np.vstack([c[:, 0, :] for c in contours]).astype(float)  # (x, y) pixel indices
    h, w = blob.shape
    inner = (pts[:, 0] > 0) & (pts[:, 0] < w - 1) & (pts[:, 1] > 0) & (pts[:, 1] < h - 1)
    total = len(pts)
    pts = pts[inner]
    if len(pts) < cfg.min_boundary_points:
        return NoDetection(f"only {len(pts)} silhouette points off the image edge")
    uv = pts + 0.5  # pixel centres
    centre = uv.mean(axis=0)
    keep = np.ones(len(uv), dtype=bool)
    threshold = cfg.outlier_px
    for _ in range(8):
        # the silhouette runs half a pixel outside the centres of the boundary pixels
        d = uv - centre
        edge = uv + 0.5 * d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-9)
        rays = intrinsics.rays(edge)
        axis, cos_a = _fit_cone(rays[keep])
        if not (0.0 < cos_a < 1.0) or axis[0] <= 0.0:
            return NoDetection("silhouette fit failed (degenerate boundary)")
        centre = intrinsics.project(axis)
        # residual in pixels: positive = inside the cone (occluder edges, calyx); only
        # inside points can be occlusion, so only they are trimmed, against a threshold
        # that tightens to 3 robust σ of the points kept (never below 0.5 px)
        alpha = math.acos(cos_a)
        ang = np.arccos(np.clip(rays @ axis, -1.0, 1.0))
        resid_px = (alpha - ang) * intrinsics.focal_px
        kept = resid_px[keep]
        sigma = 1.4826 * float(np.median(np.abs(kept - np.median(kept))))
        threshold = min(threshold, max(0.5, 3.0 * sigma)) if keep.sum() < len(keep) else threshold
        new_keep = _trim_corners(resid_px < threshold, margin=3)
        if new_keep.sum() < cfg.min_boundary_points or np.array_equal(new_keep, keep):
            break
        keep = new_keep
    sin_a = math.sin(alpha)
    rho = fruit.radius_m / sin_a
    f = intrinsics.focal_px
    # covariance: lateral from the centre pixel error; range from the unknown true radius
    # (uniform ±spread) and the pixel error of the apparent radius, dρ/dα = -ρ / tan α
    sigma_lat = rho * measurement.centre_sigma_px / f
    sigma_alpha = measurement.radius_sigma_px / f
    sigma_rho = rho * math.hypot(fruit.radius_spread_rel / math.sqrt(3.0), sigma_alpha / math.tan(alpha))
    e1 = np.cross(axis, [0.0, 0.0, 1.0])
    e1 = e1 / np.linalg.norm(e1) if np.linalg.norm(e1) > 1e-9 else np.array([0.0, 1.0, 0.0])
    U = np.column_stack((axis, e1, np.cross(axis, e1)))
    cov = U @ np.diag([sigma_rho**2, sigma_lat**2, sigma_lat**2]) @ U.T
    return Detection(
        centre_px=centre,
        radius_px=f * math.tan(alpha),
        bearing_camera=axis,
        angular_radius_rad=alpha,
        range_m=rho,
        p_camera=rho * axis,
        cov_camera=0.5 * (cov + cov.T),
        area_px=int(stats[target, cv2.CC_STAT_AREA]),
        boundary_points=int(keep.sum()),
        trimmed_fraction=1.0 - float(keep.sum()) / max(total, 1),
    )
