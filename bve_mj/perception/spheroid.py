"""The silhouette of a spheroid fruit: the cone of rays that graze it, fitted to outline rays.

A tomato is not a sphere: a round one is 5-15% flatter than it is wide, a beefsteak 20-30%,
a plum 20-40% taller. Its silhouette is then not a circle but (nearly) an ellipse, and a
circle fitted through its widest parts with the rest trimmed as "occluded" has its centre
off by the difference of the semi-axes (a 28 mm fruit of shape index 0.9: ~3 mm, always the
same way). The fruit hangs with its axis near the vertical (tilted by a few degrees), so the
axis is nearly known in the camera frame, and a spheroid about it is fitted instead.

The axis is not the vertical, though: a fruit leans on its peduncle by a few degrees, and an
upright spheroid fitted to a leaning flattened fruit's outline is off by a share of the
difference of its semi-axes (a beefsteak, k ≈ 0.7, 0.25 m away, leaning 8° across the view:
2.7 px). The lean across the line of sight turns the outline in the image, and the outline
shows it; so that lean is fitted, one small angle t along n = b₀ × u₀ / |…| (b₀ the circle
fit's bearing, u₀ the vertical): u = (u₀ + t n)/|…|, held to 0 with the fruit type's σ
(``tilt_sigma_rad``). The lean along the line of sight only changes the outline's aspect,
which the shape index takes, and is left out (fitted too, it let the outline's correlated
distortions of a tenth of a pixel pull the axis 25° in views from above: the outline's
hundreds of points outweigh any prior); so is the whole fit's lean where the view is
within 17° of the axis (|b₀ × u₀| < 0.3: the outline is the equator, whatever the lean).

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
from typing import NamedTuple

import numpy as np
from scipy.optimize import least_squares

_MIN_ACROSS = 0.3

"""|b₀ × u₀| below which the lean is not fitted (the view within 17° of the axis)."""

__all__ = [
    "SpheroidFit", "fit_spheroid", "grazing_axis_jacobian", "grazing_jacobian", "grazing_residuals",
    "tilted_axis",
]  # fmt: skip


@dataclass(frozen=True)
class SpheroidFit:
    """A fitted spheroid silhouette.

    Attributes:
        axis: unit bearing of the centre in the camera frame, (3,).
        alpha: equatorial angular radius asin(a / ρ) [rad].
        shape_index: k, polar / equatorial semi-axis.
        resid_rad: inside-positive angular residuals of every ray given, (N,).
        p: the centre in units of the equatorial radius, (3,).
        jac_rad: d(residual)/d(p, ln k) of the rays fitted [rad], (M, 4); with the axis
            lean fitted, d(residual)/d(p, ln k, t), (M, 5).
        up: the fruit's axis fitted, unit (3,) (the vertical given, where it was not fitted).
        tilt_sigma_rad: the σ the lean was held to (0: the axis was not fitted).
    """

    axis: np.ndarray
    alpha: float
    shape_index: float
    resid_rad: np.ndarray
    p: np.ndarray
    jac_rad: np.ndarray
    up: np.ndarray
    tilt_sigma_rad: float = 0.0

    def sigmas(self, point_var_rad2: float, weight: float, shape_sigma_log: float) -> tuple[float, float]:
        """1σ of the bearing (across it, the worse direction) and of α [rad] when each fitted
        ray's residual has variance ``point_var_rad2`` and counts ``weight`` (correlated
        points count less than one each); the shape's and the tilt's priors add their
        information (what the outline leaves of the tilt's play is in the centre's σ)."""
        info = weight * self.jac_rad.T @ self.jac_rad / point_var_rad2
        info[3, 3] += 1.0 / max(shape_sigma_log, 1e-3) ** 2
        if info.shape[0] > 4:
            info[4:, 4:] += np.eye(info.shape[0] - 4) / self.tilt_sigma_rad**2
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


class _Grazing(NamedTuple):
    """The terms every function of the grazing condition shares, for rays (N, 3): with
    A = I + (1/k² - 1) u uᵀ, q = Ap, c = pᵀAp - 1, β = bᵀq, γ = bᵀAb, g = β² - γc and
    ``norm`` = |∇⊥g| (the gradient across each ray, the Sampson scale)."""

    q: np.ndarray
    c: float
    beta: np.ndarray
    Ab: np.ndarray
    gamma: np.ndarray
    norm: np.ndarray


def _grazing(p: np.ndarray, shape_index: float, up: np.ndarray, rays: np.ndarray) -> _Grazing:
    A = np.eye(3) + (1.0 / shape_index**2 - 1.0) * np.outer(up, up)
    q = A @ p
    c = float(p @ q) - 1.0
    beta = rays @ q
    Ab = rays @ A  # A symmetric
    gamma = np.einsum("ij,ij->i", rays, Ab)
    grad = 2.0 * (beta[:, None] * q[None, :] - c * Ab)
    grad -= np.einsum("ij,ij->i", grad, rays)[:, None] * rays  # across the ray only
    return _Grazing(q, c, beta, Ab, gamma, np.maximum(np.linalg.norm(grad, axis=1), 1e-12))


def grazing_residuals(p: np.ndarray, shape_index: float, up: np.ndarray, rays: np.ndarray) -> np.ndarray:
    """Angular distance [rad] of unit ``rays`` (N, 3) from the silhouette of the spheroid
    centred at ``p`` (equatorial radius 1) with axis ``up`` and ``shape_index``; positive
    inside the silhouette."""
    t = _grazing(p, shape_index, up, rays)
    return (t.beta**2 - t.gamma * t.c) / t.norm


def grazing_jacobian(p: np.ndarray, shape_index: float, up: np.ndarray, rays: np.ndarray) -> np.ndarray:
    """∂(residual)/∂(p, ln k) of :func:`grazing_residuals`, (N, 4), in the Gauss-Newton
    sense: dg / |∇⊥g| (the derivative of the Sampson scale, which multiplies g, vanishes on
    the silhouette and is left out). With q = Ap, c = pᵀAp - 1, β = bᵀq, γ = bᵀAb:
    ∂g/∂p = 2β Ab - 2γ q; with dA/d(ln k) = -(2/k²) u uᵀ, u_b = uᵀb, u_p = uᵀp:
    ∂g/∂ln k = -(2/k²)(2β u_b u_p - c u_b² - γ u_p²)."""
    return _jacobians(p, shape_index, up, rays, axis=False)[0]


def grazing_axis_jacobian(p: np.ndarray, shape_index: float, up: np.ndarray, rays: np.ndarray) -> np.ndarray:
    """∂(residual)/∂u of :func:`grazing_residuals` for the axis ``up`` taken as a free vector
    (N, 3), in the Gauss-Newton sense of :func:`grazing_jacobian`. With κ = 1/k² - 1, dA =
    κ(du uᵀ + u duᵀ): ∂g/∂u = κ(2β(u_p b + u_b p) - 2c u_b b - 2γ u_p p)."""
    J_axis = _jacobians(p, shape_index, up, rays, axis=True)[1]
    assert J_axis is not None
    return J_axis


def _jacobians(
    p: np.ndarray, shape_index: float, up: np.ndarray, rays: np.ndarray, *, axis: bool
) -> tuple[np.ndarray, np.ndarray | None]:
    """:func:`grazing_jacobian` and, with ``axis``, :func:`grazing_axis_jacobian`, from one set
    of the grazing terms (the fit asks for both at every step)."""
    t = _grazing(p, shape_index, up, rays)
    ub, upp = rays @ up, float(up @ p)
    J = np.empty((len(rays), 4))
    J[:, :3] = 2.0 * (t.beta[:, None] * t.Ab - t.gamma[:, None] * t.q[None, :])
    J[:, 3] = -(2.0 / shape_index**2) * (2.0 * t.beta * ub * upp - t.c * ub**2 - t.gamma * upp**2)
    if not axis:
        return J / t.norm[:, None], None
    J_axis = (1.0 / shape_index**2 - 1.0) * (
        2.0 * t.beta[:, None] * (upp * rays + ub[:, None] * p[None, :])
        - 2.0 * t.c * ub[:, None] * rays
        - 2.0 * (t.gamma * upp)[:, None] * p[None, :]
    )
    return J / t.norm[:, None], J_axis / t.norm[:, None]


def tilted_axis(up: np.ndarray, across: np.ndarray, tilt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The axis u (3,) tilted from the unit ``up`` by the small angles ``tilt`` (m,) along the
    unit directions ``across`` (3, m) (each across ``up``), and ∂u/∂tilt (3, m)."""
    v = up + across @ tilt
    n = float(np.linalg.norm(v))
    u = v / n
    return u, (across - np.outer(u, u @ across)) / n


def fit_spheroid(
    rays: np.ndarray,
    up: np.ndarray,
    axis0: np.ndarray,
    alpha0: float,
    shape_index0: float,
    shape_sigma_log: float,
    scale_rad: float,
    tilt_sigma_rad: float = 0.0,
) -> SpheroidFit | None:
    """Least-squares spheroid silhouette through ``rays`` (N, 3), starting from the sphere
    (``axis0``, ``alpha0``) with the prior shape index; a robust loss (soft L1 at
    ``scale_rad``, about a pixel) lets a few stray points pass, and the log shape index is
    held to its prior with σ ``shape_sigma_log`` (a view along the axis cannot see it). With
    ``tilt_sigma_rad`` > 0 the axis' lean across the line of sight is fitted too, one angle
    held to 0 with that σ (none in a view within 17° of ``up``: the module's docstring);
    otherwise the axis is ``up``. None when the fit fails or ends at an
    absurd shape (k outside [0.4, 2.5])."""
    up = np.asarray(up, dtype=float) / float(np.linalg.norm(up))
    across = np.cross(np.asarray(axis0, dtype=float), up)
    tilted = tilt_sigma_rad > 0.0 and float(np.linalg.norm(across)) >= _MIN_ACROSS
    across = (across / float(np.linalg.norm(across)))[:, None] if tilted else np.zeros((3, 0))
    x0 = np.concatenate([np.asarray(axis0, dtype=float) / math.sin(alpha0), [math.log(shape_index0)]])
    if tilted:
        x0 = np.append(x0, 0.0)
    prior_w = 1.0 / max(shape_sigma_log, 1e-3)
    tilt_w = 1.0 / tilt_sigma_rad if tilted else 0.0
    prior_rows = np.zeros((2 if tilted else 1, len(x0)))
    prior_rows[0, 3] = prior_w
    if tilted:
        prior_rows[1, 4] = tilt_w

    def axis_of(x: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        return tilted_axis(up, across, x[4:]) if tilted else (up, None)

    def residuals(x: np.ndarray) -> np.ndarray:
        u, _ = axis_of(x)
        r = grazing_residuals(x[:3], math.exp(x[3]), u, rays) / scale_rad
        prior = [prior_w * (x[3] - math.log(shape_index0))]
        if tilted:
            prior.append(tilt_w * x[4])
        return np.append(r, prior)

    def jacobian(x: np.ndarray) -> np.ndarray:
        u, du = axis_of(x)
        J, J_axis = _jacobians(x[:3], math.exp(x[3]), u, rays, axis=du is not None)
        if J_axis is not None and du is not None:
            J = np.hstack([J, J_axis @ du])
        return np.vstack([J / scale_rad, prior_rows])

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
    u, _ = axis_of(sol.x)
    return SpheroidFit(
        p / n, math.asin(1.0 / n), k, grazing_residuals(p, k, u, rays), p.copy(),
        sol.jac[: len(rays)] * scale_rad, u, float(tilt_sigma_rad) if tilted else 0.0,
    )  # fmt: skip
