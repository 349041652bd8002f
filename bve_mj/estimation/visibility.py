"""Which fruit a camera should see, predicted from the tracks themselves.

The detector measures a fruit from its outline (the edge of the ripe colour against what is
behind it) and refuses one whose outline shows less than ``detector.min_arc_deg``. Where two
ripe fruit overlap in the image their shared edge is red on red: no outline of the colour.
The nearer fruit's rim there is still an edge of brightness (its limb darkens against the lit
face behind), which the detector's interior edges find (``detector.interior_edge``), so with
``rims`` only a nearer fruit's disc hides a fruit's outline; without, any other fruit's disc
does (a detector that sees only the colour's outline). A fruit wholly behind a nearer one
shows none either way. So the outline a camera sees of a fruit is its image circle less the
parts inside the image discs of the fruit that hide it and outside the image. Each fruit is
taken as a sphere (its image a circle of radius f·tan α around the projection of its centre,
α = asin(r/ρ)); leaves and unripe fruit, which the tracks do not know, are not counted.
"""

from __future__ import annotations

import math

import numpy as np

from bve_mj.geometry import VERTICAL_EPS, project_points

__all__ = ["arc_past_discs", "image_discs", "outline_shown_deg", "visible_arc_deg"]

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


def arc_past_discs(
    uv: np.ndarray,
    radius_px: np.ndarray,
    cover_uv: np.ndarray,
    cover_radius_px: np.ndarray,
    width_px: int,
    height_px: int,
) -> np.ndarray:
    """(n,) degrees of each circle (centres ``uv`` (n, 2), radii ``radius_px`` (n,) [px]) that
    lie in the image and outside every one of the discs ``cover_uv``/``cover_radius_px``
    ((k, 2)/(k,) [px]; a disc of radius 0 covers nothing)."""
    theta = np.linspace(0.0, 2.0 * math.pi, _SAMPLES, endpoint=False)
    ring = np.stack([np.cos(theta), np.sin(theta)], axis=1)  # (S, 2)
    pts = uv[:, None, :] + radius_px[:, None, None] * ring[None, :, :]  # (n, S, 2)
    shown = (pts[..., 0] >= 0.0) & (pts[..., 0] < width_px) & (pts[..., 1] >= 0.0) & (pts[..., 1] < height_px)
    if len(cover_uv):
        du = pts[:, None, :, 0] - cover_uv[None, :, None, 0]
        dv = pts[:, None, :, 1] - cover_uv[None, :, None, 1]
        shown &= ~np.any(np.hypot(du, dv) < cover_radius_px[None, :, None], axis=1)  # (n, k, S)
    return shown.sum(axis=1) * (360.0 / _SAMPLES)


def visible_arc_deg(
    centres_m: np.ndarray,
    radii_m: np.ndarray,
    p_world_camera: np.ndarray,
    R_world_camera: np.ndarray,
    focal_px: float,
    width_px: int,
    height_px: int,
    *,
    rims: bool = False,
) -> np.ndarray:
    """(n,) degrees of each fruit's outline that lie in the image and outside the image disc
    of every other fruit (with ``rims``: of every other fruit whose centre is nearer the
    camera) (0 for a fruit behind the camera). ``R_world_camera``: camera axes as columns (x
    optical axis, y left, z up)."""
    uv, rad, front = image_discs(
        centres_m, radii_m, p_world_camera, R_world_camera, focal_px, width_px, height_px
    )
    n = uv.shape[0]
    theta = np.linspace(0.0, 2.0 * math.pi, _SAMPLES, endpoint=False)
    ring = np.stack([np.cos(theta), np.sin(theta)], axis=1)  # (S, 2)
    pts = uv[:, None, :] + rad[:, None, None] * ring[None, :, :]  # (n, S, 2)
    rho = np.linalg.norm(
        np.atleast_2d(np.asarray(centres_m, dtype=float)) - np.asarray(p_world_camera), axis=1
    )
    shown = (pts[..., 0] >= 0.0) & (pts[..., 0] < width_px) & (pts[..., 1] >= 0.0) & (pts[..., 1] < height_px)
    for j in range(n):
        if not front[j]:
            continue
        inside = np.hypot(pts[..., 0] - uv[j, 0], pts[..., 1] - uv[j, 1]) < rad[j]
        inside[j] = False
        if rims:
            inside &= (rho[j] < rho)[:, None]  # a fruit farther than j keeps its rim over j
        shown &= ~inside
    arc = shown.sum(axis=1) * (360.0 / _SAMPLES)
    return np.where(front, arc, 0.0)


def outline_shown_deg(
    index: int,
    centres_m: np.ndarray,
    radii_m: np.ndarray,
    positions_m: np.ndarray,
    focal_px: float,
    width_px: int,
    height_px: int,
    *,
    rims: bool = False,
) -> np.ndarray:
    """(m,) degrees of fruit ``index``'s outline that :func:`visible_arc_deg` predicts a camera
    at each of ``positions_m`` (m, 3) sees, each camera looking at that fruit's centre
    (:func:`~bve_mj.geometry.camera_rotation`): the same numbers for m cameras at once (a
    planner that ranks many positions; 0 for a camera inside the fruit)."""
    c = np.atleast_2d(np.asarray(centres_m, dtype=float))
    r = np.asarray(radii_m, dtype=float).reshape(-1)
    p = np.atleast_2d(np.asarray(positions_m, dtype=float))
    n = c.shape[0]
    if not 0 <= index < n or r.shape[0] != n:
        raise ValueError(f"fruit index {index} out of range for {n} fruit with {r.shape[0]} radii")
    u = c[index] - p  # (m, 3)
    dist = np.linalg.norm(u, axis=1)
    ok = dist > 0.0
    x = u / np.where(ok, dist, 1.0)[:, None]
    h = np.hypot(x[:, 0], x[:, 1])
    level = h > VERTICAL_EPS
    hs = np.where(level, h, 1.0)
    y = np.column_stack(
        [np.where(level, -x[:, 1] / hs, 0.0), np.where(level, x[:, 0] / hs, 1.0), np.zeros(len(p))]
    )
    z = np.cross(x, y)
    d = c[None, :, :] - p[:, None, :]  # (m, n, 3)
    t = np.stack([np.einsum("mnk,mk->mn", d, a) for a in (x, y, z)], axis=-1)  # camera frame
    rho = np.linalg.norm(t, axis=2)
    front = (t[..., 0] > 1e-6) & (rho > r[None, :])
    tx = np.where(front, t[..., 0], 1.0)
    uv = np.stack(
        [0.5 * width_px - focal_px * t[..., 1] / tx, 0.5 * height_px - focal_px * t[..., 2] / tx], -1
    )
    alpha = np.arcsin(np.clip(r[None, :] / np.maximum(rho, 1e-12), 0.0, 1.0))
    rad = np.where(front, focal_px * np.tan(np.minimum(alpha, 1.5)), 0.0)  # (m, n)
    theta = np.linspace(0.0, 2.0 * math.pi, _SAMPLES, endpoint=False)
    ring = np.stack([np.cos(theta), np.sin(theta)], axis=1)  # (S, 2)
    pts = uv[:, index, None, :] + rad[:, index, None, None] * ring[None, :, :]  # (m, S, 2)
    shown = (pts[..., 0] >= 0.0) & (pts[..., 0] < width_px) & (pts[..., 1] >= 0.0) & (pts[..., 1] < height_px)
    inside = (
        np.hypot(pts[:, None, :, 0] - uv[:, :, None, 0], pts[:, None, :, 1] - uv[:, :, None, 1])
        < rad[:, :, None]
    )
    hides = front.copy()  # (m, n): the fruit whose disc hides fruit index's outline
    hides[:, index] = False
    if rims:
        hides &= rho < rho[:, index, None]
    shown &= ~np.any(inside & hides[:, :, None], axis=1)
    arc = shown.sum(axis=1) * (360.0 / _SAMPLES)
    return np.where(ok & front[:, index], arc, 0.0)
