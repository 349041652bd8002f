"""Joint position control in MuJoCo physics: minimum-jerk trajectories streamed to the
servo actuators, within the joints' velocity limits, then settling.

The actuators are the arm model's position servos (stiffness: full continuous torque at
0.05 rad error, critically damped, torque-limited to the Dynamixel Pro figures). Gravity
is compensated on the arm's bodies (MuJoCo ``gravcomp``): it stands in for the integral
action of the real servos' PID, which removes the steady sag a pure P servo would show.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import mujoco
import numpy as np

__all__ = ["JointTrajectoryController", "MoveReport"]


@dataclass(frozen=True)
class MoveReport:
    """How a move went.

    Attributes:
        duration_s: planned trajectory time; settle_s: extra time until settled.
        settled: joint speeds and errors fell below the thresholds before the timeout.
        tracking_error_rad: largest |q - q_ref| seen during the trajectory.
        final_error_rad: largest |q - q_target| at the end.
        steps: physics steps taken.
    """

    duration_s: float
    settle_s: float
    settled: bool
    tracking_error_rad: float
    final_error_rad: float
    steps: int


class JointTrajectoryController:
    """Drives the arm joints ``qpos_adr`` / actuators ``ctrl_ids`` to a joint target.

    Args:
        velocity_limit: joint speed limit [rad/s] (Dynamixel Pro under load: 3.0).
        settle_velocity: joints count as settled below this speed [rad/s] ...
        settle_error: ... and this error to the target [rad].
        settle_timeout_s: give up settling after this long (reported, not raised).
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        data: mujoco.MjData,
        qpos_adr: np.ndarray,
        dof_adr: np.ndarray,
        ctrl_ids: np.ndarray,
        *,
        velocity_limit: float = 3.0,
        settle_velocity: float = 0.02,
        settle_error: float = 2e-3,
        settle_timeout_s: float = 1.0,
    ) -> None:
        self.model, self.data = model, data
        self.qpos_adr, self.dof_adr, self.ctrl_ids = qpos_adr, dof_adr, ctrl_ids
        self.velocity_limit = velocity_limit
        self.settle_velocity = settle_velocity
        self.settle_error = settle_error
        self.settle_timeout_s = settle_timeout_s
        lo = model.actuator_ctrlrange[ctrl_ids, 0]
        hi = model.actuator_ctrlrange[ctrl_ids, 1]
        self._lo, self._hi = lo, hi

    @property
    def q(self) -> np.ndarray:
        return self.data.qpos[self.qpos_adr].copy()

    def hold(self, q: np.ndarray) -> None:
        """Command ``q`` (clipped to the actuator range) without stepping."""
        self.data.ctrl[self.ctrl_ids] = np.clip(q, self._lo, self._hi)

    def move_to(self, q_target: np.ndarray, on_step: Callable[[float], None] | None = None) -> MoveReport:
        """Minimum-jerk move from the current joint angles to ``q_target``, then settle.

        Duration: the slowest joint peaks at the velocity limit (min-jerk peak speed is
        1.875·Δq/T), at least 0.1 s. ``on_step(sim_time)`` is called after every physics
        step (videos sample it).
        """
        dt = self.model.opt.timestep
        q0 = self.q
        q1 = np.clip(np.asarray(q_target, dtype=float), self._lo, self._hi)
        delta = q1 - q0
        T = max(0.1, 1.875 * float(np.max(np.abs(delta))) / self.velocity_limit)
        n = max(1, int(np.ceil(T / dt)))
        worst_tracking = 0.0
        for i in range(1, n + 1):
            s = min(1.0, i * dt / T)
            blend = 10 * s**3 - 15 * s**4 + 6 * s**5
            ref = q0 + blend * delta
            self.data.ctrl[self.ctrl_ids] = ref
            mujoco.mj_step(self.model, self.data)
            if on_step is not None:
                on_step(self.data.time)
            worst_tracking = max(worst_tracking, float(np.max(np.abs(self.q - ref))))
        settle_steps = 0
        max_settle = int(np.ceil(self.settle_timeout_s / dt))
        settled = False
        while settle_steps < max_settle:
            qd = self.data.qvel[self.dof_adr]
            if np.max(np.abs(qd)) < self.settle_velocity and np.max(np.abs(self.q - q1)) < self.settle_error:
                settled = True
                break
            mujoco.mj_step(self.model, self.data)
            if on_step is not None:
                on_step(self.data.time)
            settle_steps += 1
        return MoveReport(
            duration_s=n * dt,
            settle_s=settle_steps * dt,
            settled=settled,
            tracking_error_rad=worst_tracking,
            final_error_rad=float(np.max(np.abs(self.q - q1))),
            steps=n + settle_steps,
        )
