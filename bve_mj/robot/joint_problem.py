"""The joint-space BVE's terms at a configuration q (:mod:`bve_mj.robot.planner`), cached for
SLSQP's calls, each derivative computed only when asked (SLSQP asks for values at every
point it tries, for derivatives only where it moves: about two thirds of them)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

import bve_mj.linalg as la
from bve_mj.robot.kinematics import ArmKinematics

__all__ = ["JointProblem", "LimitMargin", "UprightPreference"]

_LOOK_AXES = [1, 2, 0]  # h = (y_C·d, z_C·d, x_C·d)


@dataclass(frozen=True)
class LimitMargin:
    """A soft barrier that keeps joints off their limits: w·Σ (max(0, δ - d_i)/δ)², d_i the
    joint's distance to its nearer limit, δ a tenth of its range. Zero in the middle of the
    range. Without it the local joint-space optimiser pins joints at their limits within two
    views and strands the arm in a folded branch from which it cannot come closer."""

    kin: ArmKinematics
    weight: float
    delta: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        lo, hi = self.kin.limits.lower, self.kin.limits.upper
        object.__setattr__(self, "delta", 0.1 * (hi - lo))
        # the limits as floats for the float path (one joint of 6 at a time is ~30 numpy calls)
        floats = (lo.tolist(), hi.tolist(), self.delta.tolist()) if np.all(self.delta > 0.0) else None
        object.__setattr__(self, "_floats", floats)

    def lazy(self, q: np.ndarray) -> tuple[float, Callable[[], np.ndarray]]:
        """The barrier at q and a function that computes its gradient (n,)."""
        floats: tuple[list[float], list[float], list[float]] | None = self._floats  # type: ignore[attr-defined]
        if floats is None:
            return self._lazy_arrays(q)
        w = self.weight
        s: list[float] = []
        sign: list[float] = []
        for qi, lo, hi, delta in zip(q.tolist(), *floats, strict=True):
            # the array path's operations joint by joint, each rounded the same way
            below, above = qi - lo, hi - qi
            near_lower = below < above
            x = delta - (below if near_lower else above)
            s.append((x if x > 0.0 or x != x else 0.0) / delta)  # np.maximum(0.0, x): nan stays
            sign.append(1.0 if near_lower else -1.0)
        s_arr = np.array(s)

        def gradient() -> np.ndarray:
            c = -2.0 * w
            return np.array([c * si / di * gi for si, di, gi in zip(s, floats[2], sign, strict=True)])

        return float(w * s_arr @ s_arr), gradient

    def _lazy_arrays(self, q: np.ndarray) -> tuple[float, Callable[[], np.ndarray]]:
        lo, hi, delta = self.kin.limits.lower, self.kin.limits.upper, self.delta
        below, above = q - lo, hi - q
        near_lower = below < above
        d = np.where(near_lower, below, above)
        s = np.maximum(0.0, delta - d) / delta
        return float(
            self.weight * s @ s
        ), lambda: -2.0 * self.weight * s / delta * np.where(near_lower, 1.0, -1.0)

    def __call__(self, q: np.ndarray) -> tuple[float, np.ndarray]:
        value, gradient = self.lazy(q)
        return value, gradient()


@dataclass(frozen=True)
class UprightPreference:
    """A soft preference for an upright image: w·(1 - a/√(a² + b² + ε²)), a = z_C·ẑ and
    b = y_C·ẑ the image's up and left axes' heights (camera z is the image's up), ε = 0.05.
    Where the optical axis is not near vertical this is w·(1 - cos roll), roll the angle
    about the optical axis from the world's up to the image's up: zero upright, 2w with the
    floor at the top, whatever the axis' elevation (so it turns the camera about its axis
    and does not pull the viewpoint up or down); it fades where the axis is near vertical
    and no roll is better than another. Gradient: ∂a/∂q = J_ωᵀ(z_C × ẑ), ∂b/∂q = J_ωᵀ(y_C × ẑ)."""

    weight: float
    eps: float = 0.05

    def lazy(self, R: np.ndarray, J: np.ndarray) -> tuple[float, Callable[[], np.ndarray]]:
        """The preference at the camera rotation R (its 6×n Jacobian J) and a function that
        computes its gradient (n,)."""
        a, b = float(R[2, 2]), float(R[2, 1])
        s = a * a + b * b + self.eps * self.eps
        root = s**0.5
        w = self.weight

        def gradient() -> np.ndarray:
            # J_ωᵀ of one vector: -w((s - a²)(up × ẑ) - ab(left × ẑ))/(s√s), v × ẑ = (v_y, -v_x, 0)
            ca, cb = -w * (s - a * a) / (s * root), w * a * b / (s * root)
            up_y, left_y, up_x, left_x = float(R[1, 2]), float(R[1, 1]), float(R[0, 2]), float(R[0, 1])
            return J[3:].T @ np.array([ca * up_y + cb * left_y, -(ca * up_x + cb * left_x), 0.0])

        return w * (1.0 - a / root), gradient


@dataclass
class JointProblem:
    """Camera position, axes and Jacobian at q, and the look-at terms h = (y_C·d, z_C·d,
    x_C·d), d = unit(k̂ - c), with their Jacobian (3, n), cached for SLSQP's calls."""

    kin: ArmKinematics
    k_hat: np.ndarray
    _q: list[float] | None = None
    _pose: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
    _d: tuple[np.ndarray, float] | None = None
    _h: np.ndarray | None = None
    _dh: np.ndarray | None = None

    def at(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(p_world_camera, R_world_camera, 6×n Jacobian) at q."""
        key = q.tolist()  # equal lists of new floats: np.array_equal (0.0 == -0.0, nan != nan)
        if key != self._q:
            self._q = key
            self._pose = self.kin.camera_pose_and_jacobian(np.array(q, dtype=float))
            self._h = self._dh = None
        assert self._pose is not None
        return self._pose

    def look(self, q: np.ndarray) -> np.ndarray:
        """h at q, (3,)."""
        p, R, _ = self.at(q)
        if self._h is None:
            u = self.k_hat - p
            rho = la.norm(u)
            d = u / rho
            self._d = (d, rho)
            self._h = (d @ R)[_LOOK_AXES]
        return self._h

    def look_jacobian(self, q: np.ndarray) -> np.ndarray:
        """∂h/∂q at q, (3, n): for each camera axis a, ∂(a·d) = (ω × a)·d + a·∂d = a·[d]× ω +
        a·∂d (ω = J_ω q̇, ∂d = (d dᵀ - I) J_v q̇ / ρ): the rows y_C, z_C, x_C of Rᵀ [(d dᵀ -
        I)/ρ | [d]×] J."""
        self.look(q)
        if self._dh is None:
            _, R, J = self.at(q)
            assert self._d is not None
            d, rho = self._d
            d0, d1, d2 = d.tolist()
            # fmt: off
            B = np.array([
                [(d0 * d0 - 1.0) / rho, d0 * d1 / rho, d0 * d2 / rho, 0.0, -d2, d1],
                [d1 * d0 / rho, (d1 * d1 - 1.0) / rho, d1 * d2 / rho, d2, 0.0, -d0],
                [d2 * d0 / rho, d2 * d1 / rho, (d2 * d2 - 1.0) / rho, -d1, d0, 0.0],
            ])
            # fmt: on
            self._dh = (R.T[_LOOK_AXES] @ B) @ J
        return self._dh

    def look_at(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """h and ∂h/∂q at q."""
        return self.look(q), self.look_jacobian(q)
