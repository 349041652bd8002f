"""Arm kinematics with Pinocchio: camera pose, Jacobians, joint limits; and the same for
many configurations at once, in NumPy (:meth:`ArmKinematics.camera_poses_and_jacobians`).

Frames: the camera frame's x axis is the optical axis. Jacobians are in
LOCAL_WORLD_ALIGNED: rows 0-2 the velocity of the camera centre in world axes, rows 3-5
the angular velocity in world axes.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import pinocchio as pin

from bve_mj.errors import ConfigError
from bve_mj.robot.description import RobotDescription, get_robot

__all__ = ["CAMERA_FRAME", "ArmKinematics", "cross3"]

CAMERA_FRAME = "bve_camera"
"""Name of the camera frame added to every arm's Pinocchio model."""


@dataclass(frozen=True)
class _Limits:
    lower: np.ndarray
    upper: np.ndarray


_AXES = {"JointModelRX": 0, "JointModelRY": 1, "JointModelRZ": 2}


@dataclass(frozen=True)
class _Chain:
    """The serial chain from the base to the camera as constants: each joint's placement in
    its parent's frame (rotation, translation) and the axis it turns about (0, 1, 2 = x, y,
    z); the camera's placement in the last joint's frame."""

    rotations: tuple[np.ndarray, ...]
    translations: tuple[np.ndarray, ...]
    axes: tuple[int, ...]
    camera_rotation: np.ndarray
    camera_translation: np.ndarray

    @staticmethod
    def of(model: pin.Model, camera_frame_id: int) -> _Chain | None:
        """The chain of ``model`` up to the camera frame; None unless every joint turns about
        one of its own axes (revolute x, y or z) and each is the parent of the next."""
        kinds = [model.joints[i].shortname() for i in range(1, model.njoints)]
        frame = model.frames[camera_frame_id]
        serial = all(model.parents[i] == i - 1 for i in range(1, model.njoints))
        if not serial or frame.parentJoint != model.njoints - 1 or any(k not in _AXES for k in kinds):
            return None
        placements = [model.jointPlacements[i] for i in range(1, model.njoints)]
        return _Chain(
            tuple(m.rotation.copy() for m in placements),
            tuple(m.translation.copy() for m in placements),
            tuple(_AXES[k] for k in kinds),
            frame.placement.rotation.copy(),
            frame.placement.translation.copy(),
        )


def cross3(a: np.ndarray, b: np.ndarray, axis: int) -> np.ndarray:
    """a × b along ``axis`` (of length 3) of broadcastable arrays: ``np.cross`` without its
    moving of axes (several times faster on small stacks)."""
    a0, a1, a2 = np.moveaxis(a, axis, 0)
    b0, b1, b2 = np.moveaxis(b, axis, 0)
    return np.stack((a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0), axis=axis)


def _axis_rotations(axis: int, angles: np.ndarray) -> np.ndarray:
    """Rotations about the x, y or z axis (``axis`` 0, 1, 2) by ``angles`` (N,): (N, 3, 3)."""
    c, s = np.cos(angles), np.sin(angles)
    R = np.zeros((len(angles), 3, 3))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    R[:, axis, axis] = 1.0
    R[:, i, i], R[:, j, j] = c, c
    R[:, i, j], R[:, j, i] = -s, s
    return R


class ArmKinematics:
    """Forward kinematics and Jacobians of an arm's eye-in-hand camera.

    Args:
        robot: the description.
        limit_set: a key of ``robot.limit_sets`` ("urdf" = the file's own ranges).
    """

    def __init__(self, robot: RobotDescription, limit_set: str = "urdf") -> None:
        self.robot = robot
        path = robot.urdf_path
        if not path.is_file():
            raise ConfigError(
                "robot.urdf", str(path), "an existing URDF file (reinstall bve_mj or the robot data)"
            )
        try:
            full = pin.buildModelFromUrdf(str(path))
        except (RuntimeError, ValueError) as exc:
            first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            raise ConfigError("robot.urdf", str(path), f"a valid URDF file ({first})") from None
        missing = [j for j in robot.arm_joints if not full.existJointName(j)]
        if missing:
            raise ConfigError("robot.arm_joints", missing, f"joints of {robot.urdf_path.name}")
        lock = [
            full.getJointId(full.names[i])
            for i in range(1, full.njoints)
            if full.names[i] not in robot.arm_joints
        ]
        model = pin.buildReducedModel(full, lock, pin.neutral(full)) if lock else full
        parent = model.getFrameId(robot.camera_parent_frame)
        if parent >= len(model.frames):
            raise ConfigError("robot.camera_parent_frame", robot.camera_parent_frame, "a frame of the URDF")
        pf = model.frames[parent]
        placement = pf.placement * pin.SE3(robot.T_parent_camera[:3, :3], robot.T_parent_camera[:3, 3])
        self.camera_frame_id = model.addFrame(
            pin.Frame(CAMERA_FRAME, pf.parentJoint, parent, placement, pin.FrameType.OP_FRAME)
        )
        self.model = model
        self.data = model.createData()
        self.joint_names = tuple(model.names[i] for i in range(1, model.njoints))
        if self.joint_names != robot.arm_joints:
            raise ConfigError("robot.arm_joints", robot.arm_joints, f"the URDF order {self.joint_names}")
        if limit_set == "urdf":
            lower, upper = model.lowerPositionLimit.copy(), model.upperPositionLimit.copy()
        elif limit_set in robot.limit_sets:
            lower, upper = (np.array(x, dtype=float) for x in zip(*robot.limit_sets[limit_set], strict=True))
        else:
            allowed = ", ".join(dict.fromkeys(["urdf", *robot.limit_sets]))
            raise ConfigError("robot.joint_limits", limit_set, f"one of {allowed} for {robot.name}")
        model.lowerPositionLimit[:] = lower
        model.upperPositionLimit[:] = upper
        self.limit_set = limit_set
        self.limits = _Limits(lower, upper)
        self.nq = model.nq
        self.home = np.array(robot.home, dtype=float)
        if self.home.shape != (self.nq,):
            raise ConfigError("robot.home", robot.home, f"{self.nq} joint angles")
        self.home = self.clip(self.home)
        self._chain = _Chain.of(model, self.camera_frame_id)

    # ------------------------------------------------------------------ queries
    def clip(self, q: np.ndarray) -> np.ndarray:
        """q clipped into the joint limits."""
        return np.minimum(np.maximum(np.asarray(q, dtype=float), self.limits.lower), self.limits.upper)

    def within_limits(self, q: np.ndarray, tol: float = 1e-9) -> bool:
        q = np.asarray(q, dtype=float)
        return bool(np.all(q >= self.limits.lower - tol) and np.all(q <= self.limits.upper + tol))

    def limit_margin(self, q: np.ndarray) -> float:
        """The smallest distance of any joint to its nearer limit, as a share of that joint's
        range (0 = at a limit, 0.5 = every joint mid-range)."""
        q = np.asarray(q, dtype=float)
        lo, hi = self.limits.lower, self.limits.upper
        return float(np.min(np.minimum(q - lo, hi - q) / (hi - lo)))

    def random_configuration(self, rng: np.random.Generator) -> np.ndarray:
        """q uniform within the joint limits."""
        return rng.uniform(self.limits.lower, self.limits.upper)

    def camera_pose(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(p_world_camera (3,), R_world_camera (3, 3)) at configuration q."""
        pin.framesForwardKinematics(self.model, self.data, np.asarray(q, dtype=float))
        M = self.data.oMf[self.camera_frame_id]
        return M.translation.copy(), M.rotation.copy()

    def camera_pose_and_jacobian(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Camera position, rotation and the 6×n Jacobian (LOCAL_WORLD_ALIGNED)."""
        q = np.asarray(q, dtype=float)
        pin.computeJointJacobians(self.model, self.data, q)
        pin.updateFramePlacement(self.model, self.data, self.camera_frame_id)
        J = pin.getFrameJacobian(
            self.model, self.data, self.camera_frame_id, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        )
        M = self.data.oMf[self.camera_frame_id]
        return M.translation.copy(), M.rotation.copy(), J.copy()

    def camera_poses_and_jacobians(self, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`camera_pose_and_jacobian` of many configurations ``Q`` (N, n) at once:
        positions (N, 3), rotations (N, 3, 3), Jacobians (N, 6, n). The same values to
        rounding (NumPy products in place of Pinocchio's); an arm whose joints are not a
        serial chain of revolute x/y/z joints is computed one configuration at a time."""
        Q = np.atleast_2d(np.asarray(Q, dtype=float))
        chain = self._chain
        if chain is None:
            poses = [self.camera_pose_and_jacobian(q) for q in Q]
            return (np.array([p for p, _, _ in poses]), np.array([R for _, R, _ in poses]),
                    np.array([J for _, _, J in poses]))  # fmt: skip
        n = len(Q)
        R = np.broadcast_to(np.eye(3), (n, 3, 3))
        p = np.zeros((n, 3))
        origins, axes = [], []
        for k, (Rk, tk, axis) in enumerate(zip(chain.rotations, chain.translations, chain.axes, strict=True)):
            p = p + R @ tk
            R = (R @ Rk) @ _axis_rotations(axis, Q[:, k])
            origins.append(p)
            axes.append(R[:, :, axis])
        p_camera = p + R @ chain.camera_translation
        R_camera = R @ chain.camera_rotation
        J = np.empty((n, 6, self.nq))
        for k, (o, w) in enumerate(zip(origins, axes, strict=True)):
            J[:, 3:, k] = w
            J[:, :3, k] = cross3(w, p_camera - o, axis=1)
        return p_camera, R_camera, J


@lru_cache(maxsize=8)
def arm_kinematics(name: str, limit_set: str) -> ArmKinematics:
    """A per-process shared :class:`ArmKinematics` (Pinocchio model and data) for an arm."""
    return ArmKinematics(get_robot(name), limit_set)
