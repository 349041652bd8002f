"""Measurement models: ``predict(x)``, ``jacobian(x)`` and ``noise_cov`` for the EKF.

- :class:`RangeModel`: the paper's scalar range h(x) = ‖x - c‖ (eq. 27), R = σ_xx.
- :class:`CameraModel`: the fruit centre in the camera frame, h(x) = R_C^Wᵀ (x - c), as a
  camera measures it from the blob's pixel centre (bearing) and apparent radius (range);
  noise Σc in the camera frame, i.e. R Σc Rᵀ in the world: the model the BVE plans with.
  It is linear in x, so the EKF with it is the exact Kalman filter.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from bve_mj.errors import EstimationError

__all__ = ["CameraModel", "MeasurementModel", "RangeModel"]


class MeasurementModel(Protocol):
    """z = h(x) + v, v ~ N(0, noise_cov), for the fruit centre x in the world frame [m]."""

    @property
    def noise_cov(self) -> np.ndarray:
        """R, (m, m)."""
        ...

    def predict(self, x: np.ndarray) -> np.ndarray:
        """h(x), (m,)."""
        ...

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        """∂h/∂x, (m, 3)."""
        ...


def _check_vec3(name: str, v: np.ndarray) -> np.ndarray:
    arr = np.asarray(v, dtype=float)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise EstimationError(f"{name} must be 3 finite numbers, got {v!r}")
    return arr


@dataclass(frozen=True)
class RangeModel:
    """Range from a camera at ``p_world_camera`` [m]; variance ``variance_m2`` = σ_xx."""

    p_world_camera: np.ndarray
    variance_m2: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "p_world_camera", _check_vec3("p_world_camera", self.p_world_camera))
        if not (math.isfinite(self.variance_m2) and self.variance_m2 > 0.0):
            raise EstimationError(f"range variance must be > 0, got {self.variance_m2!r}")

    @property
    def noise_cov(self) -> np.ndarray:
        return np.array([[self.variance_m2]])

    def predict(self, x: np.ndarray) -> np.ndarray:
        return np.array([float(np.linalg.norm(np.asarray(x) - self.p_world_camera))])

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        d = np.asarray(x, dtype=float) - self.p_world_camera
        n = float(np.linalg.norm(d))
        if n == 0.0:
            raise EstimationError("range Jacobian undefined: estimate at the camera centre")
        return (d / n)[None, :]


@dataclass(frozen=True)
class CameraModel:
    """Fruit centre in the camera frame: h(x) = R_world_cameraᵀ (x - p_world_camera).

    Attributes:
        p_world_camera: camera centre [m], (3,).
        R_world_camera: camera axes as columns (x = optical axis), (3, 3).
        noise_cov_camera: Σc [m²] in the camera frame, (3, 3).
    """

    p_world_camera: np.ndarray
    R_world_camera: np.ndarray
    noise_cov_camera: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "p_world_camera", _check_vec3("p_world_camera", self.p_world_camera))
        R = np.asarray(self.R_world_camera, dtype=float)
        if R.shape != (3, 3) or not np.allclose(R.T @ R, np.eye(3), atol=1e-8):
            raise EstimationError("R_world_camera must be a 3x3 rotation matrix")
        S = np.asarray(self.noise_cov_camera, dtype=float)
        if S.shape != (3, 3) or not np.all(np.isfinite(S)):
            raise EstimationError("noise_cov_camera must be a finite 3x3 matrix")
        object.__setattr__(self, "R_world_camera", R)
        object.__setattr__(self, "noise_cov_camera", S)

    @property
    def noise_cov(self) -> np.ndarray:
        return self.noise_cov_camera

    def predict(self, x: np.ndarray) -> np.ndarray:
        return self.R_world_camera.T @ (np.asarray(x, dtype=float) - self.p_world_camera)

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        return self.R_world_camera.T.copy()
