"""Measurement models: ``predict(x)``, ``jacobian(x)`` and ``noise_cov`` for the filters.

The paper's models, over the centre (a larger state's other components are ignored):

- :class:`RangeModel`: the paper's scalar range h(x) = ‖x - c‖ (eq. 27), R = σ_xx.
- :class:`CameraModel`: the fruit centre in the camera frame, h(x) = R_C^Wᵀ (x - c), as a
  camera measures it from the blob's pixel centre (bearing) and apparent radius (range,
  with the radius the estimator assumes); noise Σc in the camera frame, i.e. R Σc Rᵀ in the
  world: the model the BVE plans with. It is linear in x, so the EKF with it is the exact
  Kalman filter.

What the detector really measures, over the centre and the radius r (state (4,) or (7,),
see :mod:`bve_mj.estimation.belief`):

- :class:`BearingSizeModel`: the image-plane bearing of the centre, as normalised image
  coordinates (t_y / t_x, t_z / t_x) of t = R_C^Wᵀ (k - c), and the apparent angular radius
  α = asin(r / ‖k - c‖);
- :class:`SizeModel`: α alone (the paper's range-only idea without a known size: with r in
  the state it is observable across views from different distances).

With the calibration biases in the state (7,), the detector's intrinsics are off by a
principal-point offset (δy, δz) [rad] and a focal-length error ε: it measures
((u + δy) / (1 + ε), (v + δz) / (1 + ε)) and atan(tan α / (1 + ε)).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from bve_mj.errors import EstimationError

__all__ = ["BearingSizeModel", "CameraModel", "MeasurementModel", "RangeModel", "SizeModel"]

_MAX_SIN_ALPHA = 0.99  # an estimate that puts the camera inside the fruit is clipped here


class MeasurementModel(Protocol):
    """z = h(x) + v, v ~ N(0, noise_cov), for the fruit state x (centre first) [m]."""

    @property
    def noise_cov(self) -> np.ndarray:
        """R, (m, m)."""
        ...

    def predict(self, x: np.ndarray) -> np.ndarray:
        """h(x), (m,)."""
        ...

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        """∂h/∂x, (m, n) for a state of n components."""
        ...


def _check_vec3(name: str, v: np.ndarray) -> np.ndarray:
    arr = np.asarray(v, dtype=float)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise EstimationError(f"{name} must be 3 finite numbers, got {v!r}")
    return arr


def _check_rotation(R: np.ndarray) -> np.ndarray:
    R = np.asarray(R, dtype=float)
    if R.shape != (3, 3) or not np.allclose(R.T @ R, np.eye(3), atol=1e-8):
        raise EstimationError("R_world_camera must be a 3x3 rotation matrix")
    return R


def _check_cov(name: str, S: np.ndarray, m: int) -> np.ndarray:
    S = np.atleast_2d(np.asarray(S, dtype=float))
    if S.shape != (m, m) or not np.all(np.isfinite(S)):
        raise EstimationError(f"{name} must be a finite {m}x{m} matrix")
    try:
        np.linalg.cholesky(0.5 * (S + S.T))
    except np.linalg.LinAlgError:
        raise EstimationError(f"{name} must be positive definite") from None
    return S


def _pad(J3: np.ndarray, n: int) -> np.ndarray:
    """A Jacobian over the centre (m, 3) as one over a state of n components."""
    if n == 3:
        return J3
    out = np.zeros((J3.shape[0], n))
    out[:, :3] = J3
    return out


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
        return np.array([float(np.linalg.norm(np.asarray(x)[:3] - self.p_world_camera))])

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        d = x[:3] - self.p_world_camera
        n = float(np.linalg.norm(d))
        if n == 0.0:
            raise EstimationError("range Jacobian undefined: estimate at the camera centre")
        return _pad((d / n)[None, :], x.shape[0])


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
        R = _check_rotation(self.R_world_camera)
        S = np.asarray(self.noise_cov_camera, dtype=float)
        if S.shape != (3, 3) or not np.all(np.isfinite(S)):
            raise EstimationError("noise_cov_camera must be a finite 3x3 matrix")
        object.__setattr__(self, "R_world_camera", R)
        object.__setattr__(self, "noise_cov_camera", S)

    @property
    def noise_cov(self) -> np.ndarray:
        return self.noise_cov_camera

    def predict(self, x: np.ndarray) -> np.ndarray:
        return self.R_world_camera.T @ (np.asarray(x, dtype=float)[:3] - self.p_world_camera)

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        return _pad(self.R_world_camera.T.copy(), np.asarray(x).shape[0])


def _state(x: np.ndarray) -> tuple[np.ndarray, float, np.ndarray | None]:
    """Centre, radius and (for a state of 7) the calibration biases of ``x``."""
    x = np.asarray(x, dtype=float)
    if x.shape not in ((4,), (7,)):
        raise EstimationError(
            f"a bearing/size measurement needs the radius in the state: (4,) or (7,), got {x.shape}"
        )
    return x[:3], float(x[3]), (x[4:7] if x.shape[0] == 7 else None)


def _angular_radius(d: np.ndarray, r: float) -> tuple[float, np.ndarray, float]:
    """α = asin(r/ρ) of a fruit at offset ``d`` = k - c, and ∂α/∂k (3,), ∂α/∂r."""
    rho = float(np.linalg.norm(d))
    if rho == 0.0:
        raise EstimationError("apparent size undefined: estimate at the camera centre")
    s = r / rho
    if s <= 0.0:
        raise EstimationError(f"apparent size undefined for a radius {r!r} <= 0")
    s = min(s, _MAX_SIN_ALPHA)
    cos_a = math.sqrt(1.0 - s * s)
    alpha = math.asin(s)
    return alpha, -(s / (rho * cos_a)) * (d / rho), 1.0 / (rho * cos_a)


def _focal(alpha: float, eps: float) -> tuple[float, float, float]:
    """α' = atan(tan α / (1 + ε)) and its derivatives in α and ε."""
    g = 1.0 + eps
    T = math.tan(alpha)
    q = T / g
    den = 1.0 + q * q
    return math.atan(q), (1.0 + T * T) / g / den, -T / (g * g) / den


@dataclass(frozen=True)
class SizeModel:
    """The apparent angular radius α = asin(r / ‖k - c‖) [rad] (state (4,) or (7,)).

    Attributes:
        p_world_camera: camera centre [m], (3,).
        variance_rad2: variance of α [rad²].
    """

    p_world_camera: np.ndarray
    variance_rad2: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "p_world_camera", _check_vec3("p_world_camera", self.p_world_camera))
        if not (math.isfinite(self.variance_rad2) and self.variance_rad2 > 0.0):
            raise EstimationError(f"apparent-size variance must be > 0, got {self.variance_rad2!r}")

    @property
    def noise_cov(self) -> np.ndarray:
        return np.array([[self.variance_rad2]])

    def predict(self, x: np.ndarray) -> np.ndarray:
        k, r, bias = _state(x)
        alpha, _, _ = _angular_radius(k - self.p_world_camera, r)
        return np.array([alpha if bias is None else _focal(alpha, float(bias[2]))[0]])

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        k, r, bias = _state(x)
        alpha, da_dk, da_dr = _angular_radius(k - self.p_world_camera, r)
        J = np.zeros((1, np.asarray(x).shape[0]))
        J[0, :3], J[0, 3] = da_dk, da_dr
        if bias is not None:
            _, g_alpha, g_eps = _focal(alpha, float(bias[2]))
            J[0, :4] *= g_alpha
            J[0, 6] = g_eps
        return J


@dataclass(frozen=True)
class BearingSizeModel:
    """The image-plane bearing of the centre and the apparent angular radius:
    z = (t_y / t_x, t_z / t_x, α), t = R_world_cameraᵀ (k - p_world_camera) (state (4,) or (7,)).

    Attributes:
        p_world_camera: camera centre [m], (3,).
        R_world_camera: camera axes as columns (x = optical axis), (3, 3).
        noise_cov_z: covariance of z, (3, 3): normalised image coordinates [rad²] and α [rad²].
    """

    p_world_camera: np.ndarray
    R_world_camera: np.ndarray
    noise_cov_z: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "p_world_camera", _check_vec3("p_world_camera", self.p_world_camera))
        object.__setattr__(self, "R_world_camera", _check_rotation(self.R_world_camera))
        object.__setattr__(self, "noise_cov_z", _check_cov("noise_cov_z", self.noise_cov_z, 3))

    @property
    def noise_cov(self) -> np.ndarray:
        return self.noise_cov_z

    def _terms(
        self, x: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, float, np.ndarray, float, np.ndarray | None]:
        k, r, bias = _state(x)
        d = k - self.p_world_camera
        t = self.R_world_camera.T @ d
        rho = float(np.linalg.norm(t))
        tx = max(float(t[0]), 1e-3 * rho)  # behind the camera: clipped (a huge NIS, gated)
        uv = np.array([t[1] / tx, t[2] / tx])
        # ∂(u, v)/∂t, then through t = Rᵀ (k - c)
        duv_dt = np.array([[-t[1] / tx**2, 1.0 / tx, 0.0], [-t[2] / tx**2, 0.0, 1.0 / tx]])
        alpha, da_dk, da_dr = _angular_radius(d, r)
        return uv, duv_dt @ self.R_world_camera.T, alpha, da_dk, da_dr, bias

    def predict(self, x: np.ndarray) -> np.ndarray:
        uv, _, alpha, _, _, bias = self._terms(x)
        if bias is None:
            return np.array([uv[0], uv[1], alpha])
        g = 1.0 + float(bias[2])
        return np.array([(uv[0] + bias[0]) / g, (uv[1] + bias[1]) / g, _focal(alpha, float(bias[2]))[0]])

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        uv, duv_dk, alpha, da_dk, da_dr, bias = self._terms(x)
        J = np.zeros((3, np.asarray(x).shape[0]))
        J[:2, :3] = duv_dk
        J[2, :3], J[2, 3] = da_dk, da_dr
        if bias is not None:
            g = 1.0 + float(bias[2])
            J[:2] /= g
            J[0, 4] = J[1, 5] = 1.0 / g
            J[0, 6] = -(uv[0] + bias[0]) / g**2
            J[1, 6] = -(uv[1] + bias[1]) / g**2
            _, g_alpha, g_eps = _focal(alpha, float(bias[2]))
            J[2, :4] *= g_alpha
            J[2, 6] = g_eps
        return J
