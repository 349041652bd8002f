"""What one view adds to the belief: the information matrix Λn(c) = Σn(c)⁻¹ and ∂Λn/∂c.

The BVE scores a candidate camera position c by fusing Λn(c) with the current precision
(paper eqs. 9-11). Two planning models (``PlannerConfig.planning_model``):

- ``paper``: Σn = R Σc Rᵀ whatever the filter measures (eq. 3), so Λn = R Σc⁻¹ Rᵀ.
- ``consistent``: the information the filter's measurement really adds. For the camera
  measurement that is again R Σc⁻¹ Rᵀ; for the paper's range-only EKF it is the rank-one
  e eᵀ/σ_xx along the viewing ray e (a range says nothing across the ray).

Views that failed: a view that measured nothing (the target hidden by its neighbours, a
leaf, too little of its outline) says where the target cannot be seen from. The planner
then expects of a view only its odds of a detection times its information,
p(c)·Λn(c), with p(c) = Π_j (1 - exp(-(1 - e(c)·d_j)/w)), e(c) the unit direction from the
estimate to c, d_j the directions of the failed views and w = 1 - cos θ₀
(:class:`FailedViewDiscount`): views within about θ₀ of a failed one are worth little, and
the BVE looks elsewhere instead of returning to the best view on paper, which it cannot
use.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from bve_mj.config import Settings
from bve_mj.geometry import camera_rotation, camera_rotation_derivative

__all__ = [
    "CameraInformation",
    "FailedViewDiscount",
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


@dataclass(frozen=True)
class FailedViewDiscount:
    """p(c)·Λn(c): ``base``'s information times the odds that a view at c detects the target,
    given the unit directions ``failed`` (k, 3) from the estimate to views that did not
    (see the module docstring); ``width_rad`` = θ₀."""

    base: ObservationInformation
    failed: np.ndarray
    width_rad: float

    def odds(self, c: np.ndarray, k_hat: np.ndarray) -> tuple[float, np.ndarray]:
        """p(c) and ∂p/∂c (3,)."""
        d = np.asarray(c, dtype=float) - k_hat
        r = float(np.linalg.norm(d))
        e = d / r
        w = 1.0 - math.cos(self.width_rad)
        u = 1.0 - self.failed @ e  # (k,) 1 - cos(angle to each failed view)
        g = np.exp(-u / w)
        q = 1.0 - g
        # ∂u_j/∂c = -(I - e eᵀ) d_j / r;  ∂q_j/∂c = (g_j / w) ∂u_j/∂c
        du = -(self.failed - np.outer(self.failed @ e, e)) / r
        dq = (g / w)[:, None] * du
        p = float(np.prod(q))
        others = np.array([np.prod(np.delete(q, j)) for j in range(len(q))])
        return p, others @ dq

    def information(self, c: np.ndarray, k_hat: np.ndarray) -> np.ndarray:
        return self.odds(c, k_hat)[0] * self.base.information(c, k_hat)

    def information_derivative(self, c: np.ndarray, k_hat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        L, dL = self.base.information_derivative(c, k_hat)
        p, dp = self.odds(c, k_hat)
        return p * L, p * dL + L[:, :, None] * dp[None, None, :]


def observation_information(settings: Settings) -> ObservationInformation:
    """The information model the planner uses under ``settings`` (``measurement.kind = "auto"``
    outside a world is the paper's range measurement; the closed loop resolves it first)."""
    sigma_c = settings.sigma_c_m2()
    if settings.planner.planning_model == "consistent" and settings.measurement.kind in ("range", "auto"):
        return RangeInformation(float(sigma_c[0, 0]))
    return CameraInformation(sigma_c)
