"""The share of a filter's covariance the declared sensor errors make: no detector error.

The claim's shape and scales (:mod:`bve_mj.estimation.claim_shape`, :class:`bve_mj.loop.
claims.Claims`) are fitted on the detector's errors. A filter's covariance also holds errors
the sensor model declares with their σ: the camera's calibration biases (a per-episode bias
the state carries, its prior N(0, σ²)) and encoder noise (a white bearing error of each view).
Those are Gaussian and as honest as their σ; scaling them with the detector's second moment
(m ≈ 0.43) made the ``realistic_sensors`` scene claim half its errors.

In the linear(ised) filter the estimate's error is P·(J₀·e₀ + Σₖ Hₖᵀ Rₖ⁻¹ vₖ) with P the
posterior covariance, J₀ the prior's information, Hₖ, Rₖ and vₖ each measurement's Jacobian,
noise covariance and noise. Its covariance therefore splits into independent parts, and the
sensors' is G = P·S·P with

    S = J_b + Σₖ Hₖᵀ Rₖ⁻¹ R_s,k Rₖ⁻¹ Hₖ,

J_b the prior's information on the calibration biases and R_s,k the encoder noise's part of
Rₖ (:func:`sensor_information`). The Jacobians are taken at one state (the current
estimate): exact for a linear model, first order for the filter's. G ⪯ P holds exactly for
a linear filter without process noise; :func:`nearest_psd` keeps P − G a covariance.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from bve_mj.estimation.belief import CALIBRATION, Belief
from bve_mj.estimation.models import MeasurementModel

__all__ = [
    "added",
    "calibration_information",
    "measurement_information",
    "nearest_psd",
    "sensor_information",
    "sensor_share",
]


def sensor_information(
    prior: Belief, measured: Iterable[tuple[MeasurementModel, np.ndarray | None]], x: np.ndarray
) -> np.ndarray | None:
    """S, (n, n): the information the declared sensor errors hold in a filter of ``prior``
    that fused ``measured`` (each model with the sensor's part of its noise covariance, None
    where it has none), linearised at ``x``. None where there is none (no biases in the state,
    no sensor noise in a measurement)."""
    info = None
    if prior.dim == 7:
        info = np.zeros((7, 7))
        info[CALIBRATION, CALIBRATION] = np.linalg.inv(prior.cov[CALIBRATION, CALIBRATION])
    for model, r_sensor in measured:
        info = added(info, measurement_information(model, r_sensor, x))
    return info


def calibration_information(dim: int, sigmas: tuple[float, float, float] | None) -> np.ndarray | None:
    """J_b, (dim, dim): the calibration biases' prior N(0, diag(σ²)) as information, in a
    state of ``dim`` components (None where it carries no biases or ``sigmas`` is None)."""
    if dim != 7 or sigmas is None:
        return None
    info = np.zeros((7, 7))
    info[CALIBRATION, CALIBRATION] = np.diag(1.0 / np.square(sigmas))
    return info


def measurement_information(
    model: MeasurementModel, sensor_cov: np.ndarray | None, x: np.ndarray
) -> np.ndarray | None:
    """Hᵀ R⁻¹ R_s R⁻¹ H at ``x``: one measurement's term of S (None where ``sensor_cov`` R_s
    is None)."""
    if sensor_cov is None:
        return None
    W = np.linalg.solve(model.noise_cov, model.jacobian(x))  # R⁻¹ H
    return W.T @ np.asarray(sensor_cov, dtype=float) @ W


def added(a: np.ndarray | None, b: np.ndarray | None) -> np.ndarray | None:
    """a + b, where None is nothing."""
    if a is None:
        return b
    return a if b is None else a + b


def sensor_share(cov: np.ndarray, information: np.ndarray | None) -> np.ndarray | None:
    """G = P·S·P (symmetric, (n, n)): the share of the covariance ``cov`` (P) the sensor
    errors of ``information`` (S, :func:`sensor_information`) make; None for None."""
    if information is None:
        return None
    P = np.asarray(cov, dtype=float)
    g = P @ information @ P
    return 0.5 * (g + g.T)


def nearest_psd(cov: np.ndarray) -> np.ndarray:
    """``cov`` symmetrised with its eigenvalues floored at 0: P − G, negative only by the
    linearisation and the centre's process noise."""
    w, v = np.linalg.eigh(0.5 * (cov + cov.T))
    return (v * np.maximum(w, 0.0)) @ v.T
