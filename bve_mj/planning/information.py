"""What one view adds to the belief: the information matrix Λn(c) = Σn(c)⁻¹ and ∂Λn/∂c.

The BVE scores a candidate camera position c by fusing Λn(c) with the current precision
(paper eqs. 9-11). Two planning models (``PlannerConfig.planning_model``):

- ``paper``: Σn = R Σc Rᵀ whatever the filter measures (eq. 3), so Λn = R Σc⁻¹ Rᵀ.
- ``consistent``: the information the filter's measurement really adds. For the camera
  measurement that is again R Σc⁻¹ Rᵀ; for the paper's range-only EKF it is the rank-one
  e eᵀ/σ_xx along the viewing ray e (a range says nothing across the ray).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from bve_mj.config import Settings
from bve_mj.geometry import camera_rotation, camera_rotation_derivative

__all__ = [
    "CameraInformation",
    "ObservationInformation",
    "RangeInformation",
    "observation_information",
]


class ObservationInformation(Protocol):
    """Λn(c) for a camera at c looking at the estimate k̂."""

    def information(self, c: np.ndarray, k_hat: np.ndarray) -> np.ndarray:
        """Λn, (3, 3) [1/m²]."""
        ...

    def information_derivative(self, c: np.ndarray, k_hat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Λn (3, 3) and ∂Λn/∂c (3, 3, 3), ``[:, :, j]`` = ∂Λn/∂c_j."""
        ...


@dataclass(frozen=True)
class CameraInformation:
    """Λn = R Σc⁻¹ Rᵀ with R the paper's camera frame (eqs. 4-8)."""

    sigma_c_m2: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "_W", np.linalg.inv(np.asarray(self.sigma_c_m2, dtype=float)))

    def information(self, c: np.ndarray, k_hat: np.ndarray) -> np.ndarray:
        R = camera_rotation(c, k_hat)
        W: np.ndarray = self._W  # type: ignore[attr-defined]
        return R @ W @ R.T

    def information_derivative(self, c: np.ndarray, k_hat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        R, dR = camera_rotation_derivative(c, k_hat)
        W: np.ndarray = self._W  # type: ignore[attr-defined]
        RW = R @ W
        T = np.einsum("ikj,lk->ilj", dR, RW)  # dR_j W Rᵀ
        return RW @ R.T, T + T.transpose(1, 0, 2)


@dataclass(frozen=True)
class RangeInformation:
    """Λn = e eᵀ / σ_xx: a range measurement informs only along the viewing ray e."""

    variance_m2: float

    def information(self, c: np.ndarray, k_hat: np.ndarray) -> np.ndarray:
        e = camera_rotation(c, k_hat)[:, 0]
        return np.outer(e, e) / self.variance_m2

    def information_derivative(self, c: np.ndarray, k_hat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        R, dR = camera_rotation_derivative(c, k_hat)
        e, de = R[:, 0], dR[:, 0, :]
        T = np.einsum("ij,k->ikj", de, e) / self.variance_m2
        return np.outer(e, e) / self.variance_m2, T + T.transpose(1, 0, 2)


def observation_information(settings: Settings) -> ObservationInformation:
    """The information model the planner uses under ``settings`` (``measurement.kind = "auto"``
    outside a world is the paper's range measurement; the closed loop resolves it first)."""
    sigma_c = settings.sigma_c_m2()
    if settings.planner.planning_model == "consistent" and settings.measurement.kind in ("range", "auto"):
        return RangeInformation(float(sigma_c[0, 0]))
    return CameraInformation(sigma_c)
