"""Look-at inverse kinematics: the camera at a given position with its optical axis through
a given point, within joint limits, the image turned upright where the arm allows.

Damped least squares (Levenberg-Marquardt) on the 6-vector residual
r = [p(q) - p*; x(q) - d], x the optical axis, d = (target - p*)/‖target - p*‖; its
Jacobian is [J_v; -[x]× J_ω]. Roll about the axis is free because x does not depend on it.
Steps are clipped into the joint limits; restarts from random configurations when a start
stalls.

With ``IkOptions.upright`` the free roll is then spent on an upright image
(:func:`level_camera`): the camera turned
about its optical axis, position and axis held, until the image's up (camera z) lies in the
vertical plane through the axis, on the sky's side. A soft preference: a turn is taken only
while the look-at holds within tolerance and no joint is pushed into the outer twentieth of its
range; whatever cannot be turned stays as the look-at left it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from bve_mj.geometry import skew
from bve_mj.robot.kinematics import ArmKinematics, cross3

__all__ = ["IkOptions", "IkResult", "image_roll_rad", "level_camera", "look_at_ik", "look_at_residuals"]


@dataclass(frozen=True, kw_only=True)
class IkOptions:
    """Look-at IK settings: tolerances [m], [rad], iteration and restart caps."""

    position_tol_m: float = 1e-4
    axis_tol_rad: float = 1e-3
    max_iterations: int = 100
    restarts: int = 20
    initial_damping: float = 1e-3
    upright: bool = False
    """Turn the image upright (:func:`level_camera`) once the look-at is solved."""


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
    Jr = np.empty((6, kin.nq))  # [J_v; -[x]× J_ω], refilled in place each iteration
    while iterations < opt.max_iterations:
        iterations += 1
        Jr[:3] = J[:3]
        np.matmul(-skew(R[:, 0]), J[3:], out=Jr[3:])
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


def look_at_residuals(
    kin: ArmKinematics, q_starts: np.ndarray, p_world_camera: np.ndarray, directions: np.ndarray,
    options: IkOptions | None = None,
) -> np.ndarray:  # fmt: skip
    """Many look-at problems solved at once from their starts, the way one start of
    :func:`look_at_ik` solves one (the same damped least squares, step for step, on
    :meth:`~bve_mj.robot.kinematics.ArmKinematics.camera_poses_and_jacobians`), returning
    only each one's final residual ‖r‖ = ‖[p(q) - p*; x(q) - d]‖ (N,). Its rounding differs
    from the single solve's, so it tells which starts are worth solving (the failures, which
    run every iteration, cost most), not the joint angles.

    ``q_starts`` (N, n), ``p_world_camera`` (N, 3), ``directions`` (N, 3) unit vectors from
    the camera to the point it looks at."""
    opt = options or IkOptions()
    p_star = np.asarray(p_world_camera, dtype=float)
    d = np.asarray(directions, dtype=float)
    q = kin.clip(q_starts)
    lam = np.full(len(q), opt.initial_damping)
    p, R, J = kin.camera_poses_and_jacobians(q)
    r = np.concatenate((p - p_star, R[:, :, 0] - d), axis=1)
    cost = np.einsum("ij,ij->i", r, r)
    active = np.ones(len(q), dtype=bool)
    eye = np.eye(kin.nq)
    for _ in range(opt.max_iterations):
        i = np.flatnonzero(active)
        if not len(i):
            break
        x = R[i, :, 0]
        Jr = np.concatenate((J[i, :3], -cross3(x[:, :, None], J[i, 3:], axis=1)), axis=1)
        g = np.einsum("kji,kj->ki", Jr, r[i])
        step = np.linalg.solve(np.einsum("kji,kjl->kil", Jr, Jr) + lam[i, None, None] * eye, -g[:, :, None])
        q_new = kin.clip(q[i] + step[:, :, 0])
        p_n, R_n, J_n = kin.camera_poses_and_jacobians(q_new)
        r_n = np.concatenate((p_n - p_star[i], R_n[:, :, 0] - d[i]), axis=1)
        cost_n = np.einsum("ij,ij->i", r_n, r_n)
        better = cost_n < cost[i]
        k = i[better]
        q[k], R[k], J[k], r[k], cost[k] = q_new[better], R_n[better], J_n[better], r_n[better], cost_n[better]
        lam[k] = np.maximum(lam[k] / 3.0, 1e-9)
        worse = i[~better]
        lam[worse] *= 5.0
        active[k[cost[k] < (0.1 * opt.position_tol_m) ** 2]] = False
        active[worse[lam[worse] > 1e6]] = False
    return np.sqrt(cost)


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
            if opt.upright:
                best_q = level_camera(kin, best_q, p_world_target, opt)
                pos_err, ang_err = _errors(kin, best_q, p_star, d)
            return IkResult(best_q, True, pos_err, ang_err, total, starts)
    pos_err, ang_err = _errors(kin, best_q, p_star, d)
    return IkResult(best_q, False, pos_err, ang_err, total, starts)


_NEAR_VERTICAL = 0.1
"""Below this cos(elevation) of the optical axis (within ~6° of straight up or down) the
image has no up to prefer: every roll is as good."""
_LEVEL_TOL_RAD = math.radians(1.0)
_LEVEL_STEP_RAD = 0.5  # the largest turn per linearised step
_LEVEL_MARGIN = 0.1  # a turn may not push a joint into the outer tenth of its range (the barrier's band)
_POLISH = IkOptions(max_iterations=30)


def image_roll_rad(R_world_camera: np.ndarray) -> float | None:
    """The image's roll: the angle about the optical axis from the world's up to the
    image's up (camera z; 0 = upright, ±π = the floor at the top), positive when the
    image's left edge (camera y) is raised; None when the optical axis is near vertical."""
    up_z, left_z = float(R_world_camera[2, 2]), float(R_world_camera[2, 1])
    if math.hypot(up_z, left_z) < _NEAR_VERTICAL:
        return None
    return math.atan2(left_z, up_z)


def level_camera(
    kin: ArmKinematics, q: np.ndarray, p_world_target: np.ndarray, options: IkOptions | None = None
) -> np.ndarray:
    """``q`` turned about the camera's optical axis towards an upright image, the camera's
    position and its look at ``p_world_target`` held.

    Each step asks for a turn of -roll (at most 0.5 rad) about the axis at zero camera
    velocity (damped least squares on the 6×n camera Jacobian), clips into the joint
    limits and re-solves the look-at from there. A step is kept only when the look-at holds
    within ``options``' tolerances, the roll shrinks, and no joint enters the outer tenth of
    its range (a twentieth) that was not already there; otherwise the best configuration so far is
    returned (``q`` itself when no turn is possible: reachability first).
    """
    opt = options or IkOptions()
    q_best = kin.clip(q)
    p_star, R = kin.camera_pose(q_best)
    u = np.asarray(p_world_target, dtype=float) - p_star
    d = u / float(np.linalg.norm(u))
    roll = image_roll_rad(R)
    margin_floor = min(kin.limit_margin(q_best), _LEVEL_MARGIN)
    polish = IkOptions(position_tol_m=opt.position_tol_m, axis_tol_rad=opt.axis_tol_rad,
                       max_iterations=_POLISH.max_iterations)  # fmt: skip
    eye = np.eye(kin.nq)
    for _ in range(12):
        if roll is None or abs(roll) <= _LEVEL_TOL_RAD:
            break
        p, R, J = kin.camera_pose_and_jacobian(q_best)
        turn = -max(-_LEVEL_STEP_RAD, min(_LEVEL_STEP_RAD, roll))
        twist = np.concatenate((p_star - p, turn * R[:, 0]))
        step = np.linalg.solve(J.T @ J + 1e-6 * eye, J.T @ twist)
        q_new, _, _ = _solve_from(kin, kin.clip(q_best + step), p_star, d, polish)
        pos_err, ang_err = _errors(kin, q_new, p_star, d)
        new_roll = image_roll_rad(kin.camera_pose(q_new)[1])
        if (
            pos_err > opt.position_tol_m
            or ang_err > opt.axis_tol_rad
            or new_roll is None
            or abs(new_roll) >= abs(roll) - 1e-4
            or kin.limit_margin(q_new) < margin_floor
        ):
            break
        q_best, roll = q_new, new_roll
    return q_best
