"""What the video draws over a frame: the detection, text and tags, the scene view with the
camera path, the estimate and its ellipsoid, and the axes."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import cv2
import numpy as np

from bve_mj.perception.detection import Detection, NoDetection

if TYPE_CHECKING:
    pass

__all__ = ["draw_detection"]


# colours (RGB)
_CYAN = (0, 255, 255)


_WHITE = (255, 255, 255)


_BLACK = (0, 0, 0)


_PATH = (40, 150, 255)  # camera path: blue


_TRUTH = (255, 40, 40)  # true fruit: red


_EST = (255, 60, 255)  # estimate and its 3σ ellipse: magenta (not a leaf or fruit colour)


_FONT = cv2.FONT_HERSHEY_SIMPLEX


def _i(x: float) -> int:
    """The nearest integer (a pixel coordinate or size)."""
    return int(np.rint(x))


def _mm(metres: float) -> str:
    """A length in millimetres with two significant digits below 10 mm ("0.04 mm", "2.3 mm")."""
    mm = 1e3 * metres
    return f"{mm:.0f} mm" if mm >= 10 else f"{mm:.1f} mm" if mm >= 1 else f"{mm:.2f} mm"


def _text(img: np.ndarray, text: str, org: tuple[int, int], scale: float = 0.5,
          colour: tuple[int, int, int] = _WHITE, thickness: int = 1) -> None:  # fmt: skip
    """Text with a dark outline, readable on any background."""
    cv2.putText(img, text, org, _FONT, scale, _BLACK, thickness + 2, cv2.LINE_AA)
    cv2.putText(img, text, org, _FONT, scale, colour, thickness, cv2.LINE_AA)


def _tag(img: np.ndarray, text: str, org: tuple[int, int], scale: float = 0.45,
         colour: tuple[int, int, int] = _WHITE) -> None:  # fmt: skip
    """Text on a dark box (a label placed in the scene)."""
    (tw, th), base = cv2.getTextSize(text, _FONT, scale, 1)
    x, y = org
    _shade(img, x - 3, y - th - 3, x + tw + 3, y + base + 1, keep=0.3)
    cv2.putText(img, text, org, _FONT, scale, colour, 1, cv2.LINE_AA)


def _shade(img: np.ndarray, x0: int, y0: int, x1: int, y1: int, keep: float = 0.35) -> None:
    """Darken a rectangle (a backdrop for text) in place."""
    h, w = img.shape[:2]
    x0, x1, y0, y1 = max(0, x0), min(w, x1), max(0, y0), min(h, y1)
    if x1 > x0 and y1 > y0:
        img[y0:y1, x0:x1] = (img[y0:y1, x0:x1] * keep).astype(np.uint8)


def _text_block(img: np.ndarray, lines: Sequence[tuple[str, tuple[int, int, int]]], top: int = 0,
                scale: float = 0.55, step: int = 24) -> None:  # fmt: skip
    """Lines of text on a darkened band across the top of the image."""
    if not lines:
        return
    _shade(img, 0, top, img.shape[1], top + 10 + step * len(lines))
    for i, (line, colour) in enumerate(lines):
        cv2.putText(img, line, (10, top + step * (i + 1)), _FONT, scale, colour, 1, cv2.LINE_AA)


def draw_detection(
    image_rgb: np.ndarray,
    det: Detection | NoDetection | None,
    caption: str = "",
    *,
    assumed_radius_m: float | None = None,
    true_range_m: float | None = None,
    true_radius_m: float | None = None,
    radius_estimate_m: tuple[float, float] | None = None,
) -> np.ndarray:
    """A copy of the image with the fitted silhouette and centre (cyan), or the reason for
    none; the caption and the measured range (and, when given, the true one) above it.

    The measured range is the detector's ρ = r / sin α from the silhouette and a fruit
    radius r: the filter's estimate ``radius_estimate_m`` (mean, σ) where the state holds
    the radius, else the assumed ``assumed_radius_m``; ``true_range_m`` is the true
    camera-to-fruit-centre distance, which differs by the ratio of the true to that radius.
    """
    img = np.ascontiguousarray(image_rgb).copy()
    lines: list[tuple[str, tuple[int, int, int]]] = []
    if caption:
        lines.append((caption, _WHITE))
    if isinstance(det, Detection):
        c = tuple(int(x) for x in np.rint(det.centre_px).astype(int))
        cv2.circle(img, c, int(np.rint(det.radius_px)), _CYAN, 2, cv2.LINE_AA)
        cv2.drawMarker(img, c, _CYAN, cv2.MARKER_CROSS, 14, 2)
        if radius_estimate_m is not None:
            r, sd = radius_estimate_m
            rho = r / math.sin(det.angular_radius_rad)
            lines.append(
                (f"range from size {rho:.3f} m (estimated r = {1e3 * r:.1f} +- {1e3 * sd:.1f} mm)", _CYAN)
            )
        else:
            assumed = "" if assumed_radius_m is None else f" (assumes r = {1e3 * assumed_radius_m:.1f} mm)"
            lines.append((f"measured range {det.range_m:.3f} m{assumed}", _CYAN))
    elif isinstance(det, NoDetection):
        lines.append((f"no detection: {det.reason}", _CYAN))
    if true_range_m is not None:
        radius = "" if true_radius_m is None else f" (true r = {1e3 * true_radius_m:.1f} mm)"
        lines.append((f"true range {true_range_m:.3f} m{radius}", (255, 120, 120)))
    _text_block(img, lines)
    return img


@dataclass(frozen=True)
class _View:
    """A free camera's pose and pinhole (from the scene MuJoCo drew), for projecting points."""

    pos: np.ndarray
    right: np.ndarray
    up: np.ndarray
    forward: np.ndarray
    focal_px: float
    centre: tuple[float, float]

    def project(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixel coordinates (N, 2) and depths (N,) of world points (N, 3)."""
        rel = np.atleast_2d(p) - self.pos
        z = rel @ self.forward
        zs = np.where(z > 1e-6, z, np.nan)
        u = self.centre[0] + self.focal_px * (rel @ self.right) / zs
        v = self.centre[1] - self.focal_px * (rel @ self.up) / zs
        return np.stack([u, v], axis=1), z

    def ellipse(
        self, mean: np.ndarray, cov: np.ndarray, k: float = 3.0
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """The k-σ ellipsoid's outline (linearised at the mean): centre px, half-axes px and
        angle [deg] packed as (centre, [a, b, angle]); None behind the camera."""
        (uv,), (z,) = self.project(mean)
        if not z > 1e-6:
            return None
        rel = mean - self.pos
        x, y = rel @ self.right, rel @ self.up
        J = (self.focal_px / z) * np.stack(
            [self.right - x / z * self.forward, -(self.up - y / z * self.forward)]
        )
        w, V = np.linalg.eigh(J @ cov @ J.T)
        a, b = k * np.sqrt(np.maximum(w[::-1], 0.0))
        angle = math.degrees(math.atan2(V[1, 1], V[0, 1]))
        return uv, np.array([a, b, angle])


def _axes(azimuth: float, elevation: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A MuJoCo free camera's forward, right and up unit vectors (degrees in)."""
    az, el = math.radians(azimuth), math.radians(elevation)
    fwd = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
    right = np.cross(fwd, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    return fwd, right, np.cross(right, fwd)


def _frame(
    points: np.ndarray,
    azimuth: float,
    elevation: float,
    fovy_deg: float,
    aspect: float,
    min_half_m: float = 0.15,
    fill: tuple[float, float] = (0.72, 0.58),
) -> tuple[np.ndarray, float]:
    """(lookat, distance) of a free camera at these angles that shows every point, the
    points filling at most ``fill`` (horizontal, vertical) of the image, and at least
    ``min_half_m`` either side of the centre (a close view of a short path)."""
    fwd, right, up = _axes(azimuth, elevation)
    coords = points @ np.stack([right, up, fwd], axis=1)
    lo, hi = coords.min(axis=0), coords.max(axis=0)
    mid = (lo + hi) / 2
    lookat = mid @ np.stack([right, up, fwd])
    ty = math.tan(math.radians(fovy_deg) / 2) * fill[1]
    tx = math.tan(math.radians(fovy_deg) / 2) * aspect * fill[0]
    rel = coords - mid
    need = np.maximum(np.abs(rel[:, 0]) / tx, np.abs(rel[:, 1]) / ty) - rel[:, 2]
    distance = max(float(need.max()), min_half_m / ty)
    return lookat, distance
