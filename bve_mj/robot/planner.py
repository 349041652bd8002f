"""Kinematic feasibility in the BVE (paper E5/E10): the next camera pose must be reachable.

Two formulations (``RobotConfig.formulation``):

- ``joint``: optimise the joint angles q. The camera position is FK(q); the loss and every
  task constraint act on it through the camera Jacobian; the optical axis must pass
  through the estimate (two equalities, y_C·d = z_C·d = 0, and x_C·d ≥ 0); joint limits are
  bounds. Seeds: the current configuration and the best of the BVE's seed points mapped
  into joint space by one pseudo-inverse step (``economical``: the second only where the
  first run fails or ends near the view just taken, closer than three quarters of a step,
  and each run stopped where its objective has stalled at a feasible iterate,
  :func:`_stalled`; the every-fruit loop's planners, two plans a view). When no seed
  reaches a feasible pose, an elastic joint-space problem (min t s.t. g_i ≤ t,
  1 - x_C·d ≤ t, step limit) turns the arm towards one, a step at a time, flagged
  ``restoring``.
- ``cartesian``: the kinematics-free BVE over the camera position with one more task
  constraint, :class:`Reachability`: the look-at IK residual at c (warm-started), with a
  finite-difference gradient. Measured: ~1000x slower and rarely feasible (the residual is
  not smooth at the edge of the reachable set); kept for comparison.

Both return plans whose IK is verified: a plan flagged feasible has a configuration within
the joint limits that puts the camera there looking at the estimate. The roll about the
optical axis, which neither the loss nor the constraints see, is then turned towards an
upright image (:func:`bve_mj.robot.ik.level_camera`).
"""

from __future__ import annotations

import dataclasses
import math
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import get_args

import numpy as np

from bve_mj.config import Formulation, LossName, Settings
from bve_mj.errors import ConfigError
from bve_mj.estimation.belief import Belief
from bve_mj.planning.baselines import CirclePlanner, FixedViewsPlanner, RandomPlanner
from bve_mj.planning.bve import SEED_DIRECTIONS, BvePlanner
from bve_mj.planning.constraints import Constraint, ConstraintName, ExtraConstraints, StepLimit, max_violation
from bve_mj.planning.plan import Planner, PlanStatus, ViewPlan
from bve_mj.planning.slsqp import minimize_slsqp
from bve_mj.robot.ik import IkOptions, IkResult, level_camera, look_at_ik
from bve_mj.robot.joint_problem import JointProblem, LimitMargin, UprightPreference
from bve_mj.robot.kinematics import ArmKinematics

__all__ = ["KinematicBvePlanner", "Reachability", "make_arm_planner"]

_AXIS_TOL_RAD = 1e-3
_PLAN_IK = IkOptions(restarts=1, max_iterations=40)  # inside a plan the seed (current q) is close
_LEFT_START = 0.75
"""``economical``: a run from the current configuration that moves the camera this share of
the step limit or more has left the view just taken: no second start (``_plan_joint``)."""
_STALL_ITERATIONS = 5
_STALL_REL = 1e-6  # a run stops once _STALL_ITERATIONS lowered f by less than this share of it
_STUCK_REL = 1e-9  # ... at an infeasible iterate: changed it by less than this (:func:`_stalled`)
_LEVEL_IK = IkOptions(position_tol_m=1e-8, axis_tol_rad=1e-6)  # a plan's roll turned, its camera held


@dataclass
class Reachability:
    """g(c) = IK residual of "camera at c looking at k̂" minus a tolerance [m] (≤ 0: reachable).

    The residual is ‖p(q) - c‖ + ρ·angle(x_C(q), k̂ - c) at the IK's best q, ρ = 0.1 m/rad.
    Warm-started from the last solution; gradient by central differences.
    """

    kin: ArmKinematics
    k_hat: np.ndarray
    q_warm: np.ndarray
    tol_m: float = 2e-4
    name: str = "reachable"
    expensive: bool = True  # an IK solve per evaluation: baselines check it last
    last: IkResult | None = field(default=None, init=False)
    _rng: np.random.Generator = field(default_factory=lambda: np.random.default_rng(0), init=False)

    def _residual(self, c: np.ndarray, restarts: int) -> float:
        res = look_at_ik(self.kin, c, self.k_hat, self.q_warm, self._rng, IkOptions(restarts=restarts))
        if res.success:
            self.q_warm = res.q
        self.last = res
        return res.position_error_m + 0.1 * res.axis_error_rad

    def value(self, c: np.ndarray) -> float:
        return self._residual(np.asarray(c, dtype=float), restarts=4) - self.tol_m

    def gradient(self, c: np.ndarray) -> np.ndarray:
        h = 1e-4
        g = np.zeros(3)
        for j in range(3):
            e = np.zeros(3)
            e[j] = h
            g[j] = (self._residual(c + e, 0) - self._residual(c - e, 0)) / (2 * h)
        return g


@dataclass
class KinematicBvePlanner:
    """The BVE with the arm's kinematic feasibility (E5, E10)."""

    settings: Settings
    loss: LossName
    constraint_names: Sequence[ConstraintName]
    kin: ArmKinematics
    q: np.ndarray
    formulation: Formulation = "joint"
    rng: np.random.Generator = field(default_factory=lambda: np.random.default_rng(0))
    economical: bool = False
    """Fewer and shorter joint-space runs (module docstring): the every-fruit loop plans two
    fruit a view with them (plan 69 -> 40-42 ms median, coverage and silent fruit as before
    on three held-out seeds); in the one-target loop they measured 5 -> 9 silent failures
    in 400 episodes of four hard scenes, not shown harmless there, so off by default."""
    _bve: BvePlanner = field(init=False)
    _left_failed: bool = field(init=False, default=False)

    def __post_init__(self) -> None:
        if self.formulation not in get_args(Formulation):
            allowed = "one of " + ", ".join(get_args(Formulation))
            raise ConfigError("robot.formulation", self.formulation, allowed)
        self.q = self.kin.clip(self.q)
        extra = self._reachability if self.formulation == "cartesian" else None
        self._bve = BvePlanner(self.settings, self.loss, self.constraint_names, extra)

    def _reachability(self, k_hat: np.ndarray) -> list[Constraint]:
        return [Reachability(self.kin, k_hat, self.q)]

    def set_configuration(self, q: np.ndarray) -> None:
        """Plan the next move from ``q`` (the encoders' reading), not from the last plan's."""
        q = np.asarray(q, dtype=float)
        if q.shape == self.q.shape and np.all(np.isfinite(q)):
            self.q = self.kin.clip(q)

    def note_failed_view(self, p_world_camera: np.ndarray, p_world_target: np.ndarray) -> None:
        """See :meth:`BvePlanner.note_failed_view`."""
        self._bve.note_failed_view(p_world_camera, p_world_target)
        self._left_failed = True

    def note_fused_view(
        self, p_world_camera: np.ndarray, p_world_target: np.ndarray, *, restart: bool = False
    ) -> None:
        """See :meth:`BvePlanner.note_fused_view`."""
        self._bve.note_fused_view(p_world_camera, p_world_target, restart=restart)

    def _level(self, q: np.ndarray, k_hat: np.ndarray, keeps: Callable[[np.ndarray], bool]) -> np.ndarray:
        """The roll neither the loss nor the constraints see, turned towards an upright
        image (``planner.upright_weight`` > 0), the camera held to 10 nm; kept only where
        ``keeps`` (the plan's own check) still accepts it."""
        if self.settings.planner.upright == 0.0:
            return q
        q_level = level_camera(self.kin, q, k_hat, _LEVEL_IK)
        return q_level if keeps(q_level) else q

    # ------------------------------------------------------------------ plan
    def plan(self, belief: Belief, p_world_camera: np.ndarray, iteration: int) -> ViewPlan:
        t0 = time.perf_counter()
        c_now = np.asarray(p_world_camera, dtype=float)
        if self.formulation == "cartesian":
            plan = self._plan_cartesian(belief, c_now, iteration, t0)
        else:
            plan = self._plan_joint(belief, c_now, iteration, t0)
        self._bve.commit(plan, belief)
        if plan.q is not None:
            self.q = plan.q.copy()
        return plan

    def _plan_cartesian(self, belief: Belief, c_now: np.ndarray, iteration: int, t0: float) -> ViewPlan:
        plan = self._bve.propose(belief, c_now, iteration)
        options = dataclasses.replace(_PLAN_IK, upright=self.settings.planner.upright > 0.0)
        ik = look_at_ik(self.kin, plan.p_world_camera, plan.p_world_target, self.q, self.rng, options)
        if ik.success:
            return dataclasses.replace(plan, plan_s=time.perf_counter() - t0, q=ik.q)
        # the optimiser's point is not reachable after all: stay where the arm is, flagged
        p, _ = self.kin.camera_pose(self.q)
        return ViewPlan(p, plan.p_world_target, "restoring", False, ik.position_error_m, plan.loss,
                        plan.iterations, time.perf_counter() - t0, self.q.copy())  # fmt: skip

    def _plan_joint(self, belief: Belief, c_now: np.ndarray, iteration: int, t0: float) -> ViewPlan:
        tol = self.settings.planner.feasibility_tol
        k_hat = belief.centre_m
        task = self._bve.task_constraints(k_hat)
        step = StepLimit(c_now, self.settings.step_m)
        every: list[Constraint] = [*task, step]
        objective = self._bve.objective(belief, iteration, self._bve.lookahead(belief, c_now, iteration))
        prob = JointProblem(self.kin, k_hat)
        bounds = list(zip(self.kin.limits.lower, self.kin.limits.upper, strict=True))

        margin = LimitMargin(self.kin, self.settings.planner.joint_margin_weight)
        upright = UprightPreference(self.settings.planner.upright)

        def f(q: np.ndarray) -> tuple[float, Callable[[], np.ndarray]]:  # gradient when asked
            p, R, J = prob.at(q)
            v, g = objective.lazy(p)
            m, dm = margin.lazy(q)
            if upright.weight == 0.0:
                return v + m, lambda: J[:3].T @ g() + dm()
            u, du = upright.lazy(R, J)
            return v + m + u, lambda: J[:3].T @ g() + dm() + du()

        def ineq(q: np.ndarray) -> np.ndarray:  # SciPy: ≥ 0
            p, _, _ = prob.at(q)
            h = prob.look(q)
            return np.array([-gi.value(p) for gi in every] + [h[2]])

        def ineq_jac(q: np.ndarray) -> np.ndarray:
            p, _, J = prob.at(q)  # one product for every task constraint's row
            G = np.array([gi.gradient(p) for gi in every])
            return np.concatenate((-(G @ J[:3]), prob.look_jacobian(q)[2:3]))

        def eq(q: np.ndarray) -> np.ndarray:
            return prob.look(q)[:2]

        def eq_jac(q: np.ndarray) -> np.ndarray:
            return prob.look_jacobian(q)[:2]

        def verify(q: np.ndarray) -> tuple[bool, float, np.ndarray]:
            p, R = self.kin.camera_pose(q)
            d = (k_hat - p) / np.linalg.norm(k_hat - p)
            axis_err = math.acos(float(np.clip(R[:, 0] @ d, -1.0, 1.0)))
            ok = self.kin.within_limits(q) and max_violation(every, p) <= tol and axis_err <= _AXIS_TOL_RAD
            return ok, axis_err, p

        # Seeds: the current configuration (often a stationary point of the loss: the view
        # just taken) and the best feasible seed direction, mapped to joint space by one
        # pseudo-inverse step; after a view that measured nothing (the current configuration
        # is then a stationary point of every term) the two best seed directions.
        # ``economical``: a run from the current configuration that ends feasible within a
        # quarter step of the step limit has left that point: no seed direction's run
        # (:data:`_LEFT_START`; six truss episodes: it did better in 4 of 63 such plans).
        # After a failed view both directions run (the second did better in 39 of 77).
        failed, self._left_failed = self._left_failed, False
        seeds = [] if failed else [self.q]
        candidates = c_now + 0.9 * step.step_m * SEED_DIRECTIONS
        scored = sorted(
            (objective.value(x), i) for i, x in enumerate(candidates) if max_violation(task, x) <= tol
        )
        if scored:
            _, _, J = prob.at(self.q)
            Jinv = np.linalg.pinv(J[:3])
            for _, i in scored[: 2 if failed else 1]:
                seeds.append(self.kin.clip(self.q + Jinv @ (candidates[i] - c_now)))
        if not seeds:
            seeds = [self.q]
        best: tuple[float, np.ndarray] | None = None
        iterations = 0
        for q0 in seeds:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                res = minimize_slsqp(
                    f, q0, ineq=[(ineq, ineq_jac)], eq=[(eq, eq_jac)], bounds=bounds,
                    maxiter=self.settings.planner.max_iterations, ftol=1e-10, lazy=True,
                    halt=_stalled(lambda q: verify(self.kin.clip(q))[0]) if self.economical else None,
                )  # fmt: skip
            iterations += int(res.nit)
            q = self.kin.clip(res.x)
            ok, _, p = verify(q)
            if ok:
                value = f(q)[0]
                if best is None or value < best[0]:
                    best = (value, q)
                left = q0 is self.q and np.linalg.norm(p - c_now) >= _LEFT_START * step.step_m
                if self.economical and left:
                    break
        if best is not None:
            q = self._level(best[1], k_hat, lambda q: verify(q)[0])
            p, _ = self.kin.camera_pose(q)
            return ViewPlan(p, k_hat, "optimal", True, max_violation(every, p), f(q)[0],
                            iterations, time.perf_counter() - t0, q)  # fmt: skip
        return self._restore(k_hat, task, step, c_now, t0, iterations)

    def _restore(
        self, k_hat: np.ndarray, task: Sequence[Constraint], step: StepLimit, c_now: np.ndarray,
        t0: float, iterations: int,
    ) -> ViewPlan:  # fmt: skip
        """No reachable feasible pose within the step: the pose within the step that violates
        the task constraints and the look-at condition least (min t s.t. g_i(c(q)) ≤ t,
        1 - x_C·d ≤ t, step(c(q)) ≤ 0, q within limits)."""
        tol = self.settings.planner.feasibility_tol
        prob = JointProblem(self.kin, k_hat)
        n = self.kin.nq
        bounds = [*zip(self.kin.limits.lower, self.kin.limits.upper, strict=True), (-1e-4, None)]

        def obj(z: np.ndarray) -> tuple[float, np.ndarray]:
            g = np.zeros(n + 1)
            g[n] = 1.0
            return float(z[n]), g

        def cons(z: np.ndarray) -> np.ndarray:  # ≥ 0
            q, t = z[:n], z[n]
            p, _, _ = prob.at(q)
            h = prob.look(q)
            return np.array([t - gi.value(p) for gi in task] + [t - (1.0 - h[2]), -step.value(p)])

        def cons_jac(z: np.ndarray) -> np.ndarray:
            q = z[:n]
            p, _, J = prob.at(q)
            dh = prob.look_jacobian(q)
            rows = [np.append(-(J[:3].T @ gi.gradient(p)), 1.0) for gi in task]
            rows.append(np.append(dh[2], 1.0))
            rows.append(np.append(-(J[:3].T @ step.gradient(p)), 0.0))
            return np.array(rows)

        p0, _, _ = prob.at(self.q)
        h0 = prob.look(self.q)
        t_start = max([1.0 - h0[2], *(gi.value(p0) for gi in task)])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = minimize_slsqp(
                obj, np.append(self.q, t_start), ineq=[(cons, cons_jac)], bounds=bounds,
                maxiter=self.settings.planner.max_iterations, ftol=1e-12,
            )  # fmt: skip
        q = self.kin.clip(res.x[:n])
        p, _ = self.kin.camera_pose(q)
        if not np.all(np.isfinite(q)) or step.value(p) > tol:  # the solver wandered: stay
            q = self.q
            p, _ = self.kin.camera_pose(q)

        def judge(q: np.ndarray) -> tuple[bool, float]:
            p, _ = self.kin.camera_pose(q)
            h = prob.look(q)
            worst = max([1.0 - h[2], *(gi.value(p) for gi in task)])
            ok = worst <= tol and math.acos(float(np.clip(h[2], -1.0, 1.0))) <= _AXIS_TOL_RAD
            return ok, worst

        def keeps(q: np.ndarray) -> bool:
            return judge(q)[0] and step.value(self.kin.camera_pose(q)[0]) <= tol

        ok, worst = judge(q)
        if ok:
            q = self._level(q, k_hat, keeps)
            p, _ = self.kin.camera_pose(q)
            ok, worst = judge(q)
        status: PlanStatus = "best_feasible" if ok else "restoring"
        return ViewPlan(p, k_hat, status, ok, max(0.0, worst), float("nan"),
                        iterations + int(res.nit), time.perf_counter() - t0, q.copy())  # fmt: skip


def _stalled(feasible: Callable[[np.ndarray], bool]) -> Callable[[np.ndarray, float], bool]:
    """A ``halt`` for one SLSQP run: stop at a ``feasible`` iterate once the last
    :data:`_STALL_ITERATIONS` iterations lowered the objective by less than
    :data:`_STALL_REL` of it. SLSQP's own test (ftol 1e-10, its constraints to 1e-9) lets a run
    creep along the step limit to the iteration cap: measured in ``truss_cluster``, runs that
    reached the cap moved the camera 5-32 mm from iteration 40 to 100 for 2e-4 to 5e-2 nats
    of objective, at ~0.4 ms an iteration. A run stuck at an infeasible point (the
    objective the same to :data:`_STUCK_REL` of it for those iterations: its line search
    failing there) is stopped too: in ``cherry_truss`` and ``truss_cluster`` (seed 9191)
    such runs held the point to the iteration cap, none becoming feasible after."""
    values: list[float] = []

    def halt(q: np.ndarray, value: float) -> bool:
        values.append(value)
        if len(values) <= _STALL_ITERATIONS:
            return False
        scale, lowered = max(1.0, abs(value)), values[-1 - _STALL_ITERATIONS] - value
        if lowered >= _STALL_REL * scale:
            return False
        return abs(lowered) < _STUCK_REL * scale or feasible(q)

    return halt


def make_arm_planner(
    settings: Settings,
    loss: LossName,
    constraint_names: Sequence[ConstraintName],
    kin: ArmKinematics,
    q_start: np.ndarray,
    rng: np.random.Generator,
    checks: ExtraConstraints | None = None,
    economical: bool = False,
) -> Planner:
    """``settings.planner.kind`` with the arm's kinematic feasibility added.

    The BVE uses ``settings.robot.formulation``; the baselines get the :class:`Reachability`
    constraint, so they too only ever choose viewpoints the arm can take, and then
    ``checks(k̂)`` (expensive constraints checked after it: the every-fruit views' clearance,
    :class:`~bve_mj.loop.arm_clearance.BaselineClearance`). The BVE ignores ``checks``;
    ``economical`` is :attr:`KinematicBvePlanner.economical` (the baselines ignore it).
    """
    kind = settings.planner.kind
    if kind == "bve":
        return KinematicBvePlanner(
            settings, loss, constraint_names, kin, q_start, settings.robot.formulation, rng, economical
        )
    reach = Reachability(kin, np.zeros(3), kin.clip(q_start))

    def extra(k_hat: np.ndarray) -> list[Constraint]:
        reach.k_hat = k_hat
        return [reach, *(checks(k_hat) if checks is not None else ())]

    if kind == "random":
        return RandomPlanner(settings, constraint_names, rng, extra)
    if kind == "fixed":
        return FixedViewsPlanner(settings, constraint_names, extra)
    return CirclePlanner(settings, constraint_names, extra)
