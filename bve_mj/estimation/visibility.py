"""Which fruit a camera should see, predicted from the tracks themselves.

The detector measures a fruit from its outline (the edge of the ripe colour against what is
behind it) and refuses one whose outline shows less than ``detector.min_arc_deg``. Where two
ripe fruit overlap in the image their shared edge is red on red, no outline, whichever is
nearer; a fruit wholly behind a nearer one shows none. So the outline a camera sees of a
fruit is its image circle less the parts inside the image discs of the other fruit and
outside the image. Each fruit is taken as a sphere (its image a circle of radius f·tan α
around the projection of its centre, α = asin(r/ρ)); leaves and unripe fruit, which the
tracks do not know, are not counted.
"""

from __future__ import annotations

import math

import numpy as np

from bve_mj.geometry import project_points

__all__ = ["image_discs", "visible_arc_deg"]

_SAMPLES = 72  # points on each outline (5° apart)


def image_discs(
    centres_m: np.ndarray,
    radii_m: np.ndarray,
    p_world_camera: np.ndarray,
    R_world_camera: np.ndarray,
    focal_px: float,
    width_px: int,
    height_px: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each fruit's image disc: centres (n, 2) [px, u right, v down], radii (n,) [px], and
    (n,) bool in front of the camera (a fruit the camera is inside of, or behind it, has no
    disc: radius 0)."""
    c = np.atleast_2d(np.asarray(centres_m, dtype=float))
    r = np.asarray(radii_m, dtype=float).reshape(-1)
    t = (c - np.asarray(p_world_camera, dtype=float)) @ np.asarray(
        R_world_camera, dtype=float
    )  # camera frame
    rho = np.linalg.norm(t, axis=1)
    front = (t[:, 0] > 1e-6) & (rho > r)
    tx = np.where(front, t[:, 0], 1.0)
    uv = project_points(np.column_stack([tx, t[:, 1:]]), focal_px, width_px, height_px)
    alpha = np.arcsin(np.clip(r / np.maximum(rho, 1e-12), 0.0, 1.0))
    radius_px = np.where(front, focal_px * np.tan(np.minimum(alpha, 1.5)), 0.0)
    return uv, radius_px, front


def visible_arc_deg(
    centres_m: np.ndarray,
    radii_m: np.ndarray,
    p_world_camera: np.ndarray,
    R_world_camera: np.ndarray,
    focal_px: float,
    width_px: int,
    height_px: int,
) -> np.ndarray:
    """(n,) degrees of each fruit's outline that lie in the image and outside every other
    fruit's image disc (0 for a fruit behind the camera). ``R_world_camera``: camera axes as
    columns (x optical axis, y left, z up)."""
    uv, rad, front = image_discs(
        centres_m, radii_m, p_world_camera, R_world_camera, focal_px, width_px, height_px
    )
    n = uv.shape[0]
    theta = np.linspace(0.0, 2.0 * math.pi, _SAMPLES, endpoint=False)
    ring = np.stack([np.cos(theta), np.sin(theta)], axis=1)  # (S, 2)
    pts = uv[:, None, :] + rad[:, None, None] * ring[None, :, :]  # (n, S, 2)
    shown = (pts[..., 0] >= 0.0) & (pts[..., 0] < width_px) & (pts[..., 1] >= 0.0) & (pts[..., 1] < height_px)
    for j in range(n):
        if not front[j]:
            continue
        inside = np.hypot(pts[..., 0] - uv[j, 0], pts[..., 1] - uv[j, 1]) < rad[j]
        inside[j] = False
        shown &= ~inside
    arc = shown.sum(axis=1) * (360.0 / _SAMPLES)
    return np.where(front, arc, 0.0)
