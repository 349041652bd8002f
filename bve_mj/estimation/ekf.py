"""Extended Kalman filter for a static fruit (paper eqs. 22-33), as pure functions.

Prediction: x stays, P ← P + Q (the paper's eq. 23 with its typo corrected); Q acts on the
centre (the radius and calibration biases of a larger state are constants).
Update: Joseph form, symmetrised; gain through ``solve``, never an explicit inverse. Any
state layout of :mod:`bve_mj.estimation.belief`.
Optional NIS gating rejects a measurement whose normalised innovation squared exceeds the
chi-square quantile of the given probability.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

import bve_mj.linalg as la
from bve_mj.errors import EstimationError
from bve_mj.estimation.belief import Belief
from bve_mj.estimation.metrics import chi2_quantile
from bve_mj.estimation.models import MeasurementModel

__all__ = ["UpdateResult", "gain", "nis_threshold", "predict", "update"]


@dataclass(frozen=True)
class UpdateResult:
    """What an update did.

    Attributes:
        belief: the posterior (the prior itself when the measurement was gated out).
        innovation: z - h(x⁻), (m,).
        nis: normalised innovation squared yᵀ S⁻¹ y.
        accepted: False when the gate rejected the measurement.
    """

    belief: Belief
    innovation: np.ndarray
    nis: float
    accepted: bool


def predict(belief: Belief, Q: np.ndarray) -> Belief:
    """Static-fruit prediction: mean unchanged, covariance P + Q (Q (3, 3) on the centre)."""
    Q = np.asarray(Q, dtype=float)
    if Q.shape != (3, 3) or not np.all(np.isfinite(Q)):
        raise EstimationError(f"process noise Q must be a finite 3x3 matrix, got shape {Q.shape}")
    if not Q.any():
        return belief
    P = np.array(belief.cov)
    P[:3, :3] += Q
    return Belief(belief.mean, P)


@lru_cache(maxsize=64)
def nis_threshold(probability: float, dof: int) -> float:
    """Chi-square quantile: the NIS gate for a measurement of ``dof`` components."""
    return float(chi2_quantile(probability, dof))


def gain(S: np.ndarray, HP: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, float]:
    """The Kalman gain P Hᵀ S⁻¹ from the innovation covariance S (symmetric) and H P (the
    cross-covariance, transposed), and the NIS yᵀ S⁻¹ y of innovation ``y``.

    Raises:
        EstimationError: if S is singular.
    """
    try:
        Sinv_y = la.solve(S, y)
        K = la.solve(S, HP).T
    except np.linalg.LinAlgError as exc:
        raise EstimationError(f"innovation covariance is singular: {exc}") from None
    return K, float(y @ Sinv_y)


def update(
    belief: Belief,
    z: np.ndarray,
    model: MeasurementModel,
    gate_probability: float | None = None,
    iterations: int = 1,
) -> UpdateResult:
    """EKF correction with measurement ``z`` of ``model``; with ``iterations`` > 1 the
    iterated EKF: the model is linearised again at the updated mean (Gauss-Newton on the
    MAP of prior and measurement) until the mean moves less than a micrometre, at most
    ``iterations`` times. One iteration is the EKF; on a linear model every iteration gives
    the same answer. The gate tests the innovation at the prior (the EKF's NIS).

    Raises:
        EstimationError: if z or the model's output is not finite or of the wrong shape.
    """
    z = np.atleast_1d(np.asarray(z, dtype=float))
    x0, P = belief.mean, belief.cov
    R = np.atleast_2d(model.noise_cov)
    n = x0.shape[0]
    x = x0
    nis, y0 = float("nan"), np.zeros(0)
    for it in range(max(1, iterations)):
        h = np.atleast_1d(model.predict(x))
        H = np.atleast_2d(model.jacobian(x))
        m = h.shape[0]
        if z.shape != (m,) or H.shape != (m, n) or R.shape != (m, m):
            raise EstimationError(
                f"measurement shapes disagree: z {z.shape}, h {h.shape}, H {H.shape}, R {R.shape}"
            )
        if not (np.all(np.isfinite(z)) and np.all(np.isfinite(H)) and np.all(np.isfinite(R))):
            raise EstimationError("measurement holds NaN or infinite values; refusing to fuse it")
        y = z - h - H @ (x0 - x)  # = z - h(x0) on the first pass
        S = H @ P @ H.T + R
        S = 0.5 * (S + S.T)
        K, nis_it = gain(S, H @ P, y)
        if it == 0:
            nis, y0 = nis_it, y
            if gate_probability is not None and nis > nis_threshold(gate_probability, m):
                return UpdateResult(belief, y, nis, False)
        x_new = x0 + K @ y
        moved = float(np.max(np.abs(x_new[:3] - x[:3])))
        x = x_new
        if moved < 1e-6:
            break
    I_KH = np.eye(n) - K @ H
    P_new = I_KH @ P @ I_KH.T + K @ R @ K.T
    return UpdateResult(Belief(x, 0.5 * (P_new + P_new.T)), y0, nis, True)
