"""The silhouette of a spheroid fruit: the cone of rays that graze it, fitted to outline rays.

A tomato is not a sphere: a round one is 5-15% flatter than it is wide, a beefsteak 20-30%,
a plum 20-40% taller. Its silhouette is then not a circle but (nearly) an ellipse, and a
circle fitted through its widest parts with the rest trimmed as "occluded" has its centre
off by the difference of the semi-axes (a 28 mm fruit of shape index 0.9: ~3 mm, always the
same way). The fruit hangs with its axis near the vertical (tilted by a few degrees), so the
axis is known in the camera frame, and a spheroid with that axis is fitted instead.

Model, in the camera frame, lengths in units of the equatorial radius a: centre p, axis u
(unit), shape index k = polar / equatorial semi-axis; the surface is (x - p)ᵀ A (x - p) = 1
with A = I + (1/k² - 1) u uᵀ. A ray b from the camera grazes it when the quadratic
t² bᵀAb - 2t bᵀAp + pᵀAp - 1 has a double root:

    g(b) = (bᵀAp)² - (bᵀAb)(pᵀAp - 1) = 0,  g > 0 for rays that hit it.

The residual of a boundary ray is the Sampson distance g / |∇⊥g| (an angle; positive inside
the silhouette), which is the angular distance to the silhouette to first order. Scale is
not observable (p, a → λp, λa give the same cone): the fit gives the bearing p/|p|, the
equatorial angular radius asin(1/|p|) and k; the range comes from the radius the estimator
assumes for a, as for a sphere.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

__all__ = ["SpheroidFit", "fit_spheroid", "grazing_jacobian", "grazing_residuals"]


@dataclass(frozen=True)
class SpheroidFit:
    """A fitted spheroid silhouette.

    Attributes:
        axis: unit bearing of the centre in the camera frame, (3,).
        alpha: equatorial angular radius asin(a / ρ) [rad].
        shape_index: k, polar / equatorial semi-axis.
        resid_rad: inside-positive angular residuals of every ray given, (N,).
        p: the centre in units of the equatorial radius, (3,).
        jac_rad: d(residual)/d(p, ln k) of the rays fitted [rad], (M, 4).
    """

    axis: np.ndarray
    alpha: float
    shape_index: float
    resid_rad: np.ndarray
    p: np.ndarray
    jac_rad: np.ndarray

    def sigmas(self, point_var_rad2: float, weight: float, shape_sigma_log: float) -> tuple[float, float]:
        """1σ of the bearing (across it, the worse direction) and of α [rad] when each fitted
        ray's residual has variance ``point_var_rad2`` and counts ``weight`` (correlated
        points count less than one each); the shape prior adds its information."""
        info = weight * self.jac_rad.T @ self.jac_rad / point_var_rad2
        info[3, 3] += 1.0 / max(shape_sigma_log, 1e-3) ** 2
        try:
            C = np.linalg.inv(info)[:3, :3]
        except np.linalg.LinAlgError:
            return math.inf, math.inf
        return self._bearing_alpha_sigmas(C)

    def _bearing_alpha_sigmas(self, C: np.ndarray) -> tuple[float, float]:
        """1σ of the bearing across it (worse direction) and of α [rad] for a covariance C of p."""
        n = float(np.linalg.norm(self.p))
        a = self.p / n
        P = (np.eye(3) - np.outer(a, a)) / n  # d(axis)/dp
        g = -a / (n * n * math.sqrt(1.0 - 1.0 / (n * n)))  # dα/dp, α = asin(1/|p|)
        lateral = np.linalg.eigvalsh(P @ C @ P.T)
        return math.sqrt(max(float(lateral[-1]), 0.0)), math.sqrt(max(float(g @ C @ g), 0.0))


def grazing_jacobian(p: np.ndarray, shape_index: float, up: np.ndarray, rays: np.ndarray) -> np.ndarray:
    """∂(residual)/∂(p, ln k) of :func:`grazing_residuals`, (N, 4), in the Gauss-Newton
    sense: dg / |∇⊥g| (the derivative of the Sampson scale, which multiplies g, vanishes on
    the silhouette and is left out). With q = Ap, c = pᵀAp - 1, β = bᵀq, γ = bᵀAb:
    ∂g/∂p = 2β Ab - 2γ q; with dA/d(ln k) = -(2/k²) u uᵀ, u_b = uᵀb, u_p = uᵀp:
    ∂g/∂ln k = -(2/k²)(2β u_b u_p - c u_b² - γ u_p²)."""
    k2 = shape_index**2
    A = np.eye(3) + (1.0 / k2 - 1.0) * np.outer(up, up)
    q = A @ p
    c = float(p @ q) - 1.0
    beta = rays @ q
    Ab = rays @ A
    gamma = np.einsum("ij,ij->i", rays, Ab)
    grad = 2.0 * (beta[:, None] * q[None, :] - c * Ab)
    grad -= np.einsum("ij,ij->i", grad, rays)[:, None] * rays
    norm = np.maximum(np.linalg.norm(grad, axis=1), 1e-12)
    ub, upp = rays @ up, float(up @ p)
    J = np.empty((len(rays), 4))
    J[:, :3] = 2.0 * (beta[:, None] * Ab - gamma[:, None] * q[None, :])
    J[:, 3] = -(2.0 / k2) * (2.0 * beta * ub * upp - c * ub**2 - gamma * upp**2)
    return J / norm[:, None]


def grazing_residuals(p: np.ndarray, shape_index: float, up: np.ndarray, rays: np.ndarray) -> np.ndarray:
    """Angular distance [rad] of unit ``rays`` (N, 3) from the silhouette of the spheroid
    centred at ``p`` (equatorial radius 1) with axis ``up`` and ``shape_index``; positive
    inside the silhouette."""
    A = np.eye(3) + (1.0 / shape_index**2 - 1.0) * np.outer(up, up)
    Ap = A @ p
    c = float(p @ Ap) - 1.0
    bAp = rays @ Ap
    Ab = rays @ A  # A symmetric
    bAb = np.einsum("ij,ij->i", rays, Ab)
    g = bAp**2 - bAb * c
    grad = 2.0 * (bAp[:, None] * Ap[None, :] - c * Ab)
    grad -= np.einsum("ij,ij->i", grad, rays)[:, None] * rays  # across the ray only
    return g / np.maximum(np.linalg.norm(grad, axis=1), 1e-12)


def fit_spheroid(
    rays: np.ndarray,
    up: np.ndarray,
    axis0: np.ndarray,
    alpha0: float,
    shape_index0: float,
    shape_sigma_log: float,
    scale_rad: float,
) -> SpheroidFit | None:
    """Least-squares spheroid silhouette through ``rays`` (N, 3), starting from the sphere
    (``axis0``, ``alpha0``) with the prior shape index; a robust loss (soft L1 at
    ``scale_rad``, about a pixel) lets a few stray points pass, and the log shape index is
    held to its prior with σ ``shape_sigma_log`` (a view along the axis cannot see it).
    None when the fit fails or ends at an absurd shape (k outside [0.4, 2.5])."""
    up = np.asarray(up, dtype=float) / float(np.linalg.norm(up))
    x0 = np.concatenate([np.asarray(axis0, dtype=float) / math.sin(alpha0), [math.log(shape_index0)]])
    prior_w = 1.0 / max(shape_sigma_log, 1e-3)

    def residuals(x: np.ndarray) -> np.ndarray:
        r = grazing_residuals(x[:3], math.exp(x[3]), up, rays) / scale_rad
        return np.append(r, prior_w * (x[3] - math.log(shape_index0)))

    prior_row = np.array([[0.0, 0.0, 0.0, prior_w]])

    def jacobian(x: np.ndarray) -> np.ndarray:
        return np.vstack([grazing_jacobian(x[:3], math.exp(x[3]), up, rays) / scale_rad, prior_row])

    try:
        # a fit that runs away (rays no spheroid near the start explains: a plum cut by its
        # neighbours) overflows on its way to an absurd shape, refused below: not a warning
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            sol = least_squares(
                residuals, x0, jac=jacobian, loss="soft_l1", f_scale=1.0, x_scale="jac", max_nfev=60
            )
    except (ValueError, OverflowError, np.linalg.LinAlgError):
        return None
    p, k = sol.x[:3], math.exp(float(sol.x[3]))
    n = float(np.linalg.norm(p))
    if not (np.all(np.isfinite(sol.x)) and n > 1.0 and 0.4 <= k <= 2.5 and p[0] > 0.0):
        return None
    return SpheroidFit(
        p / n, math.asin(1.0 / n), k, grazing_residuals(p, k, up, rays), p.copy(), sol.jac[:-1] * scale_rad
    )
