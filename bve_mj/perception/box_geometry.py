"""The bounding box of a fruit's image, and the fruit a box means.

A fruit is an ellipsoid: centre C and shape Q in the camera frame, the points t with
(t - C)ᵀ Q⁻¹ (t - C) ≤ 1; a spheroid of equatorial radius r, shape index k (height / width)
and axis e has Q = r² (I + (k² - 1) e eᵀ). An image column u is the plane through the
camera centre t_y = a t_x, a = (c_u - u) / f its normalised coordinate (paper frame: x optical
axis, y left, z up; pixels u right, v down; c_u, c_v the principal point). The box's left and
right edges are the two such planes tangent to the ellipsoid; a plane with normal n is
tangent where (n·C)² = nᵀ Q n, for n = (-a, 1, 0) a quadratic in a:

    (C_x² - Q_xx) a² - 2 (C_x C_y - Q_xy) a + (C_y² - Q_yy) = 0,

and the top and bottom edges likewise in b = (c_v - v) / f with the z components
(:func:`ellipsoid_box`). It is exact off the optical axis too, where the image is an ellipse
and the box's centre is not the image of the fruit's centre.

Inverting (:func:`fit_box`): a box gives four numbers; a spheroid of known shape (the
prior's shape index, its axis the world's vertical where the caller knows it, else a sphere)
has three, up to scale: the direction of its centre, z_0 = (a_0, b_0) = (C_y / C_x, C_z / C_x),
and s = r / C_x. They are fitted by Gauss-Newton from the sphere's closed form. With
independent corner errors of σ [px] (σ_n = σ / f normalised), their covariance is
σ_n² (JᵀJ)⁻¹, J the corners' Jacobian (4 × 3); the unknown true shape index (σ_k) adds
σ_k² g gᵀ, g = (JᵀJ)⁻¹ Jᵀ ∂corners/∂k. Near the optical axis this is the plain rule: centre
= the box's centre, σ = σ_px / √2 per coordinate (two corners each); apparent radius = half
the mean of width and height, σ = σ_px / 2 (four corners). The measurement is
z = (a_0, b_0, α) with α = asin(s / ‖(1, a_0, b_0)‖) the apparent angular radius of the
equator, the bearing/size model's (:class:`bve_mj.estimation.models.BearingSizeModel`), and
its covariance follows through ∂z/∂(a_0, b_0, s).

The fourth number checks the box: the residual along the direction the three cannot explain
(JᵀJ's left null space) is χ²(1) under the noise; a box whose aspect ratio no fruit of that
shape projects to (a fruit cut by an occluder or the image edge, not a fruit) is refused."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from bve_mj.perception.detection import Intrinsics

__all__ = ["BoxFit", "ellipsoid_box", "fit_box", "spheroid_shape"]

_CHI2_1_999 = 10.828  # χ²(1) quantile at 0.999: the box's misfit to a projected spheroid


def spheroid_shape(radius_m: float, shape_index: float, axis: np.ndarray | None) -> np.ndarray:
    """Q (3, 3) of a spheroid of equatorial radius ``radius_m`` and shape index (height / width)
    ``shape_index`` about the unit ``axis`` (None: a sphere)."""
    Q = np.eye(3) * radius_m**2
    if axis is not None:
        e = np.asarray(axis, dtype=float)
        e = e / np.linalg.norm(e)
        Q += radius_m**2 * (shape_index**2 - 1.0) * np.outer(e, e)
    return Q


def _edges(C: np.ndarray, Q: np.ndarray, i: int) -> tuple[float, float] | None:
    """The normalised coordinates (low, high) of the two planes t_i = c t_x tangent to the
    ellipsoid (C, Q), i = 1 (columns, a) or 2 (rows, b); None when it reaches behind the camera."""
    A = C[0] ** 2 - Q[0, 0]
    B = C[0] * C[i] - Q[0, i]
    D = C[i] ** 2 - Q[i, i]
    disc = B * B - A * D
    if not (A > 0.0 and disc >= 0.0):
        return None
    root = math.sqrt(disc)
    return (B - root) / A, (B + root) / A


def _normalised_box(C: np.ndarray, Q: np.ndarray) -> np.ndarray | None:
    """(a_high, b_high, a_low, b_low): the box's left, top, right, bottom edges, normalised."""
    a = _edges(C, Q, 1)
    b = _edges(C, Q, 2)
    if a is None or b is None:
        return None
    return np.array([a[1], b[1], a[0], b[0]])


def ellipsoid_box(
    centre_camera: np.ndarray, shape_camera: np.ndarray, intrinsics: Intrinsics
) -> np.ndarray | None:
    """The bounding box (u_min, v_min, u_max, v_max) [px, continuous] of the image of the
    ellipsoid with centre ``centre_camera`` (3,) [m] and shape ``shape_camera`` (3, 3) [m²]
    in the camera frame (not clipped to the image); None when it is not wholly in front of
    the camera (its image is unbounded)."""
    C = np.asarray(centre_camera, dtype=float)
    Q = np.asarray(shape_camera, dtype=float)
    n = _normalised_box(C, Q)
    if n is None:
        return None
    return _to_px(n, intrinsics)


def _principal(intrinsics: Intrinsics) -> tuple[float, float]:
    return (
        0.5 * intrinsics.width_px + intrinsics.cx_offset_px,
        0.5 * intrinsics.height_px + intrinsics.cy_offset_px,
    )


def _to_px(n: np.ndarray, intrinsics: Intrinsics) -> np.ndarray:
    cu, cv = _principal(intrinsics)
    f = intrinsics.focal_px
    return np.array([cu - f * n[0], cv - f * n[1], cu - f * n[2], cv - f * n[3]])


@dataclass(frozen=True)
class BoxFit:
    """The spheroid a box means.

    Attributes:
        z: (a_0, b_0, α): the bearing of its centre as normalised image coordinates
            (t_y / t_x, t_z / t_x) and its apparent angular radius (of the equator) [rad], (3,).
        cov_z: covariance of z [rad²], (3, 3).
        chi2: the box's misfit to the projected spheroid, χ²(1) under the corner noise.
        centre_px: the image of the centre's bearing (u, v) [px], (2,).
    """

    z: np.ndarray
    cov_z: np.ndarray
    chi2: float
    centre_px: np.ndarray


def _sphere_start(n: np.ndarray) -> np.ndarray:
    """(a_0, b_0, s) of the sphere whose box is closest to ``n``: per axis, the tangent lines
    c = lo, hi of a sphere at (1, c_0) with s satisfy (c_0 - c)² = s² (1 + c²)."""
    out = []
    s = []
    for lo, hi in ((n[2], n[0]), (n[3], n[1])):
        w_lo, w_hi = math.sqrt(1.0 + lo * lo), math.sqrt(1.0 + hi * hi)
        c0 = (lo * w_hi + hi * w_lo) / (w_lo + w_hi)
        out.append(c0)
        s.append((c0 - lo) / w_lo)
    return np.array([out[0], out[1], 0.5 * (s[0] + s[1])])


def _model(theta: np.ndarray, M: np.ndarray) -> np.ndarray | None:
    C = np.array([1.0, theta[0], theta[1]])
    if not theta[2] > 0.0:
        return None
    return _normalised_box(C, theta[2] ** 2 * M)


def _jacobian(f: Callable[[np.ndarray], np.ndarray | None], theta: np.ndarray) -> np.ndarray | None:
    """Central differences of ``f`` (θ → (4,) or None) at θ, (4, len θ)."""
    J = np.empty((4, len(theta)))
    for j in range(len(theta)):
        h = 1e-7 * max(1.0, abs(float(theta[j])))
        up, down = theta.copy(), theta.copy()
        up[j] += h
        down[j] -= h
        fu, fd = f(up), f(down)
        if fu is None or fd is None:
            return None
        J[:, j] = (fu - fd) / (2.0 * h)
    return J


def fit_box(
    xyxy: np.ndarray,
    intrinsics: Intrinsics,
    sigma_px: float,
    *,
    up_camera: np.ndarray | None = None,
    shape_index: float = 1.0,
    shape_sigma: float = 0.0,
) -> BoxFit | str:
    """The spheroid whose image a box (u_min, v_min, u_max, v_max) [px] bounds, or why not.

    Args:
        intrinsics: the camera the box was seen with.
        sigma_px: 1σ of each corner coordinate [px], independent.
        up_camera: the fruit's axis (the world's vertical) in the camera frame, unit (3,), if
            known: a spheroid of ``shape_index`` about it; None: a sphere.
        shape_index: height / width of the fruit the prior expects.
        shape_sigma: 1σ of the true shape index about it (its share of the apparent size's
            error, and of the box's misfit).
    Returns:
        a :class:`BoxFit`, or a reason string (no spheroid in front of the camera projects to
        this box, or the box's aspect ratio is too far from any that does).
    """
    f = intrinsics.focal_px
    cu, cv = _principal(intrinsics)
    box = np.asarray(xyxy, dtype=float).reshape(-1)
    m = np.array([(cu - box[0]) / f, (cv - box[1]) / f, (cu - box[2]) / f, (cv - box[3]) / f])
    axis = None
    if up_camera is not None:
        up = np.asarray(up_camera, dtype=float).reshape(-1)
        if up.shape == (3,) and np.all(np.isfinite(up)) and np.linalg.norm(up) > 1e-9:
            axis = up / np.linalg.norm(up)
    k = float(shape_index) if axis is not None else 1.0
    M = spheroid_shape(1.0, k, axis)

    def model(theta: np.ndarray) -> np.ndarray | None:
        return _model(theta, M)

    theta = _sphere_start(m)
    r = model(theta)
    if r is None:
        return "no fruit in front of the camera projects to this box (it spans too wide an angle)"
    r = r - m
    for _ in range(30):
        J = _jacobian(model, theta)
        if J is None:
            break
        step, *_ = np.linalg.lstsq(J, -r, rcond=None)
        t = 1.0
        moved = False
        for _ in range(12):  # halve the step until the misfit falls
            cand = theta + t * step
            rc = model(cand)
            if rc is not None and float(np.sum((rc - m) ** 2)) <= float(np.sum(r**2)):
                theta, r, moved = cand, rc - m, True
                break
            t *= 0.5
        if not moved or float(np.max(np.abs(t * step))) < 1e-13:
            break
    J = _jacobian(model, theta)
    if J is None:
        return "no fruit in front of the camera projects to this box"
    JtJ = J.T @ J
    if not np.all(np.isfinite(JtJ)) or np.linalg.cond(JtJ) > 1e12:
        return "the box does not fix a fruit's bearing and size (degenerate)"
    sigma_n = sigma_px / f
    JtJ_inv = np.linalg.inv(JtJ)
    cov_theta = sigma_n**2 * JtJ_inv
    S = sigma_n**2 * np.eye(4)  # the corners' covariance, for the misfit test
    if shape_sigma > 0.0:
        if axis is not None:  # the true shape index moves the corners along ∂n/∂k
            e = axis

            def by_shape(kk: np.ndarray) -> np.ndarray | None:
                return _model(theta, spheroid_shape(1.0, float(kk[0]), e))

            Jk = _jacobian(by_shape, np.array([k]))
            if Jk is not None:
                g = JtJ_inv @ J.T @ Jk[:, 0]
                cov_theta = cov_theta + shape_sigma**2 * np.outer(g, g)
                S = S + shape_sigma**2 * np.outer(Jk[:, 0], Jk[:, 0])
        else:  # a spheroid about an unknown axis: its size seen is off by up to half the spread
            cov_theta[2, 2] += (0.5 * theta[2] * shape_sigma) ** 2
            S = S + (theta[2] * shape_sigma) ** 2 * np.eye(4)
    U, _, _ = np.linalg.svd(J)
    null = U[:, 3]
    chi2 = float((null @ r) ** 2 / (null @ S @ null))
    a0, b0, s = (float(x) for x in theta)
    norm = math.sqrt(1.0 + a0 * a0 + b0 * b0)
    sin_a = s / norm
    if not 0.0 < sin_a < 1.0:
        return "no fruit in front of the camera projects to this box"
    alpha = math.asin(sin_a)
    cos_a = math.cos(alpha)
    G = np.eye(3)
    G[2] = [-s * a0 / (norm**3 * cos_a), -s * b0 / (norm**3 * cos_a), 1.0 / (norm * cos_a)]
    cov_z = G @ cov_theta @ G.T
    cov_z = 0.5 * (cov_z + cov_z.T)
    centre_px = np.array([cu - f * a0, cv - f * b0])
    if chi2 > _CHI2_1_999:
        return (
            f"box {box.round(1).tolist()} is not the shape of a fruit's image (aspect misfit "
            f"chi2 {chi2:.1f} > {_CHI2_1_999:g}): cut by an occluder, or not a fruit"
        )
    return BoxFit(np.array([a0, b0, alpha]), cov_z, chi2, centre_px)
