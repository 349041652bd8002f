"""Unscented Kalman filter update (the paper's future work), beside the EKF's and with the
same interface: ``update(belief, z, model, gate_probability)`` over any measurement model
(only ``predict`` and ``noise_cov`` are used: no Jacobian).

Sigma points: Julier's unscented transform with κ = 3 - n: 2n + 1 points, the mean and
±√3 σ along the columns of the covariance's Cholesky factor (each axis then carries a
Gaussian's kurtosis, whatever n), mean weights ((3 - n)/3, 1/6, ...). Its centre covariance
weight, (3 - n)/3, is negative for n > 3 and can make the posterior indefinite; it is raised
to 0 (in the scaled form: α = 1, β = n/3 - 1), so every covariance weight is non-negative and
the posterior P - C S⁻¹ Cᵀ, a Schur complement of a positive semi-definite joint covariance,
stays positive definite. The price: the spread of a quadratic term is slightly overstated
(for h = x₀² and n = 4, variance 4m²s² + 7s⁴/3 instead of 4m²s² + 2s⁴; the EKF gives
4m²s²). The prediction step is the EKF's (static fruit: P + Q, exact). Iterated like the
EKF where the model is nonlinear (posterior linearisation: :func:`update`).
"""

from __future__ import annotations

import numpy as np

from bve_mj.errors import EstimationError
from bve_mj.estimation.belief import Belief
from bve_mj.estimation.ekf import UpdateResult, gain, nis_threshold
from bve_mj.estimation.models import MeasurementModel

__all__ = ["sigma_points", "update"]

_SPREAD = 3.0  # n + λ: sigma points at ±√3 σ


def sigma_points(belief: Belief) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The 2n + 1 sigma points (2n + 1, n) and their mean and covariance weights."""
    x, P = belief.mean, belief.cov
    n = x.shape[0]
    L = np.linalg.cholesky(_SPREAD * P)
    X = np.vstack([x, x + L.T, x - L.T])
    wm = np.full(2 * n + 1, 0.5 / _SPREAD)
    wc = wm.copy()
    wm[0] = (_SPREAD - n) / _SPREAD
    wc[0] = max(wm[0], 0.0)
    return X, wm, wc


def _regression(
    belief: Belief, model: MeasurementModel
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Statistical linear regression of the model over ``belief`` by the sigma points:
    h(x) ≈ A x + b with residual covariance Ω. Returns (A, b, Ω, predicted mean)."""
    X, wm, wc = sigma_points(belief)
    Z = np.array([np.atleast_1d(model.predict(xi)) for xi in X])
    if not np.all(np.isfinite(Z)):
        raise EstimationError("measurement holds NaN or infinite values; refusing to fuse it")
    z_hat = wm @ Z
    dZ = Z - z_hat
    dX = X - belief.mean
    Szz = (wc[:, None] * dZ).T @ dZ
    C = (wc[:, None] * dX).T @ dZ  # cross-covariance (n, m)
    A = np.linalg.solve(belief.cov, C).T  # Cᵀ P⁻¹ (m, n)
    omega = Szz - A @ belief.cov @ A.T
    return A, z_hat - A @ belief.mean, 0.5 * (omega + omega.T), z_hat


def update(
    belief: Belief,
    z: np.ndarray,
    model: MeasurementModel,
    gate_probability: float | None = None,
    iterations: int = 1,
) -> UpdateResult:
    """UKF correction with measurement ``z`` of ``model``; with ``iterations`` > 1 the
    iterated posterior linearisation filter (García-Fernández et al., 2015): the sigma-point
    regression of the model is taken again over the updated belief and the prior is updated
    with it, until the mean moves less than a micrometre, at most ``iterations`` times. One
    iteration is the UKF (its regression is over the prior, ±√3 σ wide: from a prior 5 cm
    long along the ray, the apparent size's slope there is not its slope at the posterior,
    and the single-pass posterior claims too much). The gate tests the UKF's innovation.

    Raises:
        EstimationError: if z or the model's output is not finite or of the wrong shape.
    """
    z = np.atleast_1d(np.asarray(z, dtype=float))
    R = np.atleast_2d(model.noise_cov)
    x0, P0 = belief.mean, belief.cov
    n = x0.shape[0]
    current = belief
    nis, y0 = float("nan"), np.zeros(0)
    for it in range(max(1, iterations)):
        A, b, omega, z_hat = _regression(current, model)
        m = z_hat.shape[0]
        if z.shape != (m,) or R.shape != (m, m) or A.shape != (m, n):
            raise EstimationError(f"measurement shapes disagree: z {z.shape}, h {z_hat.shape}, R {R.shape}")
        if not (np.all(np.isfinite(z)) and np.all(np.isfinite(R))):
            raise EstimationError("measurement holds NaN or infinite values; refusing to fuse it")
        S = A @ P0 @ A.T + omega + R
        S = 0.5 * (S + S.T)
        y = z - A @ x0 - b  # = z - ẑ on the first pass
        K, nis_it = gain(S, A @ P0, y)  # P0 Aᵀ S⁻¹
        if it == 0:
            nis, y0 = nis_it, y
            if gate_probability is not None and nis > nis_threshold(gate_probability, m):
                return UpdateResult(belief, y, nis, False)
        P_new = P0 - K @ S @ K.T
        x_new = x0 + K @ y
        moved = float(np.max(np.abs(x_new[:3] - current.mean[:3])))
        current = Belief(x_new, 0.5 * (P_new + P_new.T))
        if moved < 1e-6:
            break
    return UpdateResult(current, y0, nis, True)
