"""What one view adds to the belief: the information matrix Λn(c) = Σn(c)⁻¹ and ∂Λn/∂c.

The BVE scores a candidate camera position c by fusing Λn(c) with the current precision
(paper eqs. 9-11). The information is over the whole state (its mean x̂: the centre k̂
first, then the radius and the calibration biases where the state holds them). Planning
models (``PlannerConfig.planning_model``, for the centre-only state):

- ``paper``: Σn = R Σc Rᵀ whatever the filter measures (eq. 3), so Λn = R Σc⁻¹ Rᵀ.
- ``consistent``: the information the filter's measurement really adds. For the camera
  measurement that is again R Σc⁻¹ Rᵀ; for the paper's range-only EKF it is the rank-one
  e eᵀ/σ_xx along the viewing ray e (a range says nothing across the ray).

With the radius in the state the planner plans with the filter's own model
(:class:`~bve_mj.planning.size_information.SizeInformation`): Hᵀ W H of the bearing/size (or
size-only) measurement of a camera at c looking at k̂, with the noise the calibrated model
expects of a whole fruit at that distance. The losses score the centre's block of the fused covariance.

Views that failed: a view that measured nothing (the target hidden by its neighbours, a
leaf, too little of its outline) says where the target cannot be seen from. The planner
then expects of a view only its odds of a detection times its information,
p(c)·Λn(c), with p(c) = Π_j (1 - exp(-(1 - e(c)·d_j)/w)), e(c) the unit direction from the
estimate to c, d_j the directions of the failed views and w = 1 - cos θ₀
(:class:`FailedViewDiscount`): views within about θ₀ of a failed one are worth little, and
the BVE looks elsewhere instead of returning to the best view on paper, which it cannot
use. Where failed views surround the camera, p(c) is ~0 within a whole step and this term
goes flat; the loss then also counts the failed views near c
(:class:`~bve_mj.planning.losses.UntriedTerm`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from bve_mj.config import Settings
from bve_mj.geometry import (
    camera_frame,
    camera_rotation,
    camera_rotation_derivative,
    frame_rotation,
    frame_rotation_derivative,
)
from bve_mj.planning.size_information import SizeInformation, size_information

__all__ = [
    "CameraInformation",
    "FailedViewDiscount",
    "ObservationInformation",
    "RangeInformation",
    "failed_view_floats",
    "failed_view_rows",
    "information_lazy",
    "observation_information",
]

Derivative = Callable[[], np.ndarray]
"""∂Λn/∂c (n, n, 3), computed when called (see :func:`information_lazy`)."""


def _pad_derivative(dL: np.ndarray, n: int) -> np.ndarray:
    """∂Λ/∂c on the centre (3, 3, 3) as one on a state of n (the derivative of :func:`_pad`)."""
    if n == 3:
        return dL
    dLn = np.zeros((n, n, 3))
    dLn[:3, :3] = dL
    return dLn


def _pad(L: np.ndarray, dL: np.ndarray | None, n: int) -> tuple[np.ndarray, np.ndarray | None]:
    """Information (3, 3) on the centre (and its derivative (3, 3, 3)) as one on a state of n."""
    if n == 3:
        return L, dL
    Ln = np.zeros((n, n))
    Ln[:3, :3] = L
    return Ln, None if dL is None else _pad_derivative(dL, n)


class ObservationInformation(Protocol):
    """Λn(c) for a camera at c looking at the estimate, over the state whose mean is x̂ (n,)."""

    def information(self, c: np.ndarray, x_hat: np.ndarray) -> np.ndarray:
        """Λn, (n, n)."""
        ...

    def information_derivative(self, c: np.ndarray, x_hat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Λn (n, n) and ∂Λn/∂c (n, n, 3), ``[:, :, j]`` = ∂Λn/∂c_j."""
        ...


@dataclass(frozen=True)
class CameraInformation:
    """Λn = R Σc⁻¹ Rᵀ with R the paper's camera frame (eqs. 4-8)."""

    sigma_c_m2: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "_W", np.linalg.inv(np.asarray(self.sigma_c_m2, dtype=float)))

    def information(self, c: np.ndarray, x_hat: np.ndarray) -> np.ndarray:
        R = camera_rotation(c, x_hat[:3])
        W: np.ndarray = self._W  # type: ignore[attr-defined]
        return _pad(R @ W @ R.T, None, len(x_hat))[0]

    def information_derivative(self, c: np.ndarray, x_hat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        R, dR = camera_rotation_derivative(c, x_hat[:3])
        W: np.ndarray = self._W  # type: ignore[attr-defined]
        RW = R @ W
        T = np.einsum("ikj,lk->ilj", dR, RW)  # dR_j W Rᵀ
        L, dL = _pad(RW @ R.T, T + T.transpose(1, 0, 2), len(x_hat))
        assert dL is not None
        return L, dL

    def information_lazy(self, c: np.ndarray, x_hat: np.ndarray) -> tuple[np.ndarray, Derivative]:
        """:meth:`information_derivative` with ∂Λn/∂c computed when asked (same bits)."""
        frame = camera_frame(c, x_hat[:3])
        R = frame_rotation(frame)
        RW = R @ self._W  # type: ignore[attr-defined]
        n = len(x_hat)

        def derivative() -> np.ndarray:
            T = np.einsum("ikj,lk->ilj", frame_rotation_derivative(frame), RW)
            return _pad_derivative(T + T.transpose(1, 0, 2), n)

        return _pad(RW @ R.T, None, n)[0], derivative


@dataclass(frozen=True)
class RangeInformation:
    """Λn = e eᵀ / σ_xx: a range measurement informs only along the viewing ray e."""

    variance_m2: float

    def information(self, c: np.ndarray, x_hat: np.ndarray) -> np.ndarray:
        e = camera_rotation(c, x_hat[:3])[:, 0]
        return _pad(np.outer(e, e) / self.variance_m2, None, len(x_hat))[0]

    def information_derivative(self, c: np.ndarray, x_hat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        R, dR = camera_rotation_derivative(c, x_hat[:3])
        e, de = R[:, 0], dR[:, 0, :]
        T = np.einsum("ij,k->ikj", de, e) / self.variance_m2
        L, dL = _pad(np.outer(e, e) / self.variance_m2, T + T.transpose(1, 0, 2), len(x_hat))
        assert dL is not None
        return L, dL

    def information_lazy(self, c: np.ndarray, x_hat: np.ndarray) -> tuple[np.ndarray, Derivative]:
        """:meth:`information_derivative` with ∂Λn/∂c computed when asked (same bits)."""
        frame = camera_frame(c, x_hat[:3])
        e = frame_rotation(frame)[:, 0]
        n = len(x_hat)

        def derivative() -> np.ndarray:
            T = np.einsum("ij,k->ikj", frame_rotation_derivative(frame)[:, 0, :], e) / self.variance_m2
            return _pad_derivative(T + T.transpose(1, 0, 2), n)

        return _pad(np.outer(e, e) / self.variance_m2, None, n)[0], derivative


def failed_view_floats(
    rows: Sequence[tuple[float, float, float]], c: np.ndarray, k_hat: np.ndarray, width_rad: float
) -> tuple[tuple[float, float, float], float, list[float], list[float]]:
    """How near the camera at c is to each failed view, seen from the estimate ``k_hat``:
    e(c) (3 floats, the unit direction k̂ → c), r = ‖c - k̂‖, e·d_j and g_j(c) = exp(-(1 -
    e·d_j)/w) for the failed views' unit directions d_j (``rows``), w = 1 - cos ``width_rad``
    (∂(e·d_j)/∂c = (d_j - (e·d_j) e)/r). In floats: a handful of failed views is a few
    dozen float operations, several times faster than the same on (k, 3) arrays.

    Raises:
        ValueError: where c is the estimate (no direction) or not finite."""
    k0, k1, k2 = np.asarray(k_hat, dtype=float)[:3].tolist()
    c0, c1, c2 = np.asarray(c, dtype=float).tolist()
    d0, d1, d2 = c0 - k0, c1 - k1, c2 - k2
    r = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    if not r > 0.0:  # nan too
        raise ValueError("the camera is at the estimate: no direction to weigh failed views by")
    e0, e1, e2 = d0 / r, d1 / r, d2 / r
    w = 1.0 - math.cos(width_rad)
    cos = [a * e0 + b * e1 + z * e2 for a, b, z in rows]
    return (e0, e1, e2), r, cos, [math.exp(-(1.0 - cj) / w) for cj in cos]


def failed_view_rows(failed: np.ndarray) -> tuple[tuple[float, float, float], ...]:
    """The failed views' unit directions (k, 3) as rows of floats (:func:`failed_view_floats`)."""
    return tuple((a, b, z) for a, b, z in np.asarray(failed, dtype=float).reshape(-1, 3).tolist())


@dataclass(frozen=True)
class FailedViewDiscount:
    """p(c)·Λn(c): ``base``'s information times the odds that a view at c detects the target,
    given the unit directions ``failed`` (k, 3) from the estimate to views that did not
    (see the module docstring); ``width_rad`` = θ₀."""

    base: ObservationInformation
    failed: np.ndarray
    width_rad: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "_rows", failed_view_rows(self.failed))

    def odds(self, c: np.ndarray, x_hat: np.ndarray) -> tuple[float, np.ndarray]:
        """p(c) and ∂p/∂c (3,)."""
        p, dp = self.odds_lazy(c, x_hat)
        return p, dp()

    def odds_lazy(self, c: np.ndarray, x_hat: np.ndarray) -> tuple[float, Callable[[], np.ndarray]]:
        """p(c), and a function that computes ∂p/∂c (3,) (in floats: :func:`failed_view_floats`).

        Raises:
            ValueError: where c is the estimate (no direction)."""
        rows: tuple[tuple[float, float, float], ...] = self._rows  # type: ignore[attr-defined]
        (e0, e1, e2), r, cos, g = failed_view_floats(rows, c, x_hat, self.width_rad)
        w = 1.0 - math.cos(self.width_rad)
        p = 1.0
        for gj in g:
            p *= 1.0 - gj

        def gradient() -> np.ndarray:
            # Σ_j Π_{i≠j}(1 - g_i)·(-g_j/w)·∂(e·d_j)/∂c, ∂(e·d_j)/∂c = (d_j - (e·d_j) e)/r; the
            # products Π_{i≠j} as those before j times those after it (no division: a
            # factor of 0 is exact there)
            after = [1.0] * len(g)
            for j in range(len(g) - 2, -1, -1):
                after[j] = after[j + 1] * (1.0 - g[j + 1])
            before, out0, out1, out2 = 1.0, 0.0, 0.0, 0.0
            for (a, b, z), cj, gj, aj in zip(rows, cos, g, after, strict=True):
                f = before * aj * -gj / w / r
                out0 += f * (a - cj * e0)
                out1 += f * (b - cj * e1)
                out2 += f * (z - cj * e2)
                before *= 1.0 - gj
            return np.array([out0, out1, out2])

        return p, gradient

    def information(self, c: np.ndarray, x_hat: np.ndarray) -> np.ndarray:
        return self.odds(c, x_hat)[0] * self.base.information(c, x_hat)

    def information_derivative(self, c: np.ndarray, x_hat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        L, dL = self.base.information_derivative(c, x_hat)
        p, dp = self.odds(c, x_hat)
        return p * L, p * dL + L[:, :, None] * dp[None, None, :]

    def information_lazy(self, c: np.ndarray, x_hat: np.ndarray) -> tuple[np.ndarray, Derivative]:
        """:meth:`information_derivative` with ∂Λn/∂c computed when asked (same bits)."""
        L, dL = information_lazy(self.base, c, x_hat)
        p, dp = self.odds_lazy(c, x_hat)
        return p * L, lambda: p * dL() + L[:, :, None] * dp()[None, None, :]


def observation_information(settings: Settings) -> ObservationInformation:
    """The information model the planner uses under ``settings`` (``measurement.kind = "auto"``
    outside a world is the paper's range measurement; the closed loop resolves it first; with
    the radius in the state, :func:`size_information`)."""
    if settings.filter.state == "centre_radius":
        return size_information(settings)
    sigma_c = settings.sigma_c_m2()
    if settings.planner.planning_model == "consistent" and settings.measurement.kind in ("range", "auto"):
        return RangeInformation(float(sigma_c[0, 0]))
    return CameraInformation(sigma_c)


def information_lazy(
    info: ObservationInformation, c: np.ndarray, x_hat: np.ndarray
) -> tuple[np.ndarray, Derivative]:
    """``info.information_derivative(c, x_hat)`` as Λn and a function that computes ∂Λn/∂c, the
    same bits either way: the optimiser asks for the derivative at half to two thirds of the points
    it evaluates (not at the line search's trials). Models without a lazy form compute both."""
    if isinstance(info, (CameraInformation, RangeInformation, FailedViewDiscount, SizeInformation)):
        return info.information_lazy(c, x_hat)
    L, dL = info.information_derivative(c, x_hat)
    return L, lambda: dL
