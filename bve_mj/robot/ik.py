"""Look-at inverse kinematics: the camera at a given position with its optical axis through
a given point, roll about the axis free, within joint limits.

Damped least squares (Levenberg-Marquardt) on the 6-vector residual
r = [p(q) - p*; x(q) - d], x the optical axis, d = (target - p*)/‖target - p*‖; its
Jacobian is [J_v; -[x]× J_ω]. Roll is free because x does not depend on it. Steps are
clipped into the joint limits; restarts from random configurations when a start stalls.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from bve_mj.geometry import skew
from bve_mj.robot.kinematics import ArmKinematics

__all__ = ["IkOptions", "IkResult", "look_at_ik"]


@dataclass(frozen=True, kw_only=True)
class IkOptions:
    """Look-at IK settings: tolerances [m], [rad], iteration and restart caps."""

    position_tol_m: float = 1e-4
    axis_tol_rad: float = 1e-3
    max_iterations: int = 100
    restarts: int = 20
    initial_damping: float = 1e-3


@dataclass(frozen=True)
class IkResult:
    """The IK answer: the best configuration found and how good it is.

    Attributes:
        q: joint angles within the limits [rad], (n,).
        success: both residuals within tolerance.
        position_error_m: ‖p(q) - p*‖.
        axis_error_rad: angle between the optical axis and the direction to the target.
        iterations: LM iterations over all starts.
        starts: starts tried (1 = the seed sufficed).
    """

    q: np.ndarray
    success: bool
    position_error_m: float
    axis_error_rad: float
    iterations: int
    starts: int


def _errors(kin: ArmKinematics, q: np.ndarray, p_star: np.ndarray, d: np.ndarray) -> tuple[float, float]:
    p, R = kin.camera_pose(q)
    c = float(np.clip(R[:, 0] @ d, -1.0, 1.0))
    return float(np.linalg.norm(p - p_star)), math.acos(c)


def _solve_from(
    kin: ArmKinematics, q0: np.ndarray, p_star: np.ndarray, d: np.ndarray, opt: IkOptions
) -> tuple[np.ndarray, float, int]:
    q = kin.clip(q0)
    lam = opt.initial_damping
    p, R, J = kin.camera_pose_and_jacobian(q)
    r = np.concatenate((p - p_star, R[:, 0] - d))
    cost = float(r @ r)
    iterations = 0
    eye = np.eye(kin.nq)
    while iterations < opt.max_iterations:
        iterations += 1
        x = R[:, 0]
        Jr = np.vstack((J[:3], -skew(x) @ J[3:]))
        g = Jr.T @ r
        step = np.linalg.solve(Jr.T @ Jr + lam * eye, -g)
        q_new = kin.clip(q + step)
        p_n, R_n, J_n = kin.camera_pose_and_jacobian(q_new)
        r_n = np.concatenate((p_n - p_star, R_n[:, 0] - d))
        cost_n = float(r_n @ r_n)
        if cost_n < cost:
            q, p, R, J, r, cost = q_new, p_n, R_n, J_n, r_n, cost_n
            lam = max(lam / 3.0, 1e-9)
            if cost < (0.1 * opt.position_tol_m) ** 2:
                break
        else:
            lam *= 5.0
            if lam > 1e6:
                break
    return q, cost, iterations


def look_at_ik(
    kin: ArmKinematics,
    p_world_camera: np.ndarray,
    p_world_target: np.ndarray,
    q_seed: np.ndarray | None = None,
    rng: np.random.Generator | None = None,
    options: IkOptions | None = None,
) -> IkResult:
    """Joint angles that put the camera at ``p_world_camera`` looking at ``p_world_target``.

    Starts from ``q_seed`` (default: home), then from random configurations (``rng``,
    default seeded 0 for repeatability) until the residuals are within tolerance or the
    restarts are spent. Always returns the best configuration found, within the limits.
    """
    opt = options or IkOptions()
    p_star = np.asarray(p_world_camera, dtype=float)
    u = np.asarray(p_world_target, dtype=float) - p_star
    n = float(np.linalg.norm(u))
    if n == 0.0 or not np.all(np.isfinite(u)):
        raise ValueError("look-at IK needs a target distinct from the camera position")
    d = u / n
    rng = rng or np.random.default_rng(0)
    seed = kin.home if q_seed is None else np.asarray(q_seed, dtype=float)
    best_q, best_cost, total = kin.clip(seed), math.inf, 0
    starts = 0
    for starts in range(1, opt.restarts + 2):
        q0 = seed if starts == 1 else kin.random_configuration(rng)
        q, cost, it = _solve_from(kin, q0, p_star, d, opt)
        total += it
        if cost < best_cost:
            best_q, best_cost = q, cost
        pos_err, ang_err = _errors(kin, best_q, p_star, d)
        if pos_err <= opt.position_tol_m and ang_err <= opt.axis_tol_rad:
            return IkResult(best_q, True, pos_err, ang_err, total, starts)
    pos_err, ang_err = _errors(kin, best_q, p_star, d)
    return IkResult(best_q, False, pos_err, ang_err, total, starts)
