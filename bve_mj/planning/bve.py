"""The best-viewpoint estimator (BVE): the next camera position minimising the fused
observation covariance under the paper's constraints.

Each plan: (1) if the current position violates a task constraint, restore feasibility
within the step limit (:func:`feasible_start`); if no point within reach is feasible,
return the least-violating one flagged ``restoring``; (2) score the feasible start and 14
fixed points on the step sphere (6 axis and 8 diagonal directions, at 0.9 r_d) and
minimise the loss from the best ``starts`` of them with SLSQP or trust-constr; (3) keep the
best answer that is feasible and no worse than its start, else the best start, flagged
``best_feasible``. An infeasible viewpoint is never returned unflagged.

Why several starts: the position just observed from is a stationary point of the loss (the
filter's covariance is aligned with the ray it has just measured along), so a local
optimiser started there alone never moves.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

import bve_mj.linalg as la
from bve_mj.config import LossName, Settings
from bve_mj.estimation.belief import Belief
from bve_mj.planning.constraints import (
    Constraint,
    ConstraintName,
    ExtraConstraints,
    StepLimit,
    build_constraints,
    check_constraint_names,
    max_violation,
)
from bve_mj.planning.horizon import HorizonObjective, horizon_constraints
from bve_mj.planning.information import FailedViewDiscount, ObservationInformation, observation_information
from bve_mj.planning.losses import (
    ApproachTerm,
    DispersionLoss,
    LossTerm,
    MaxEigenvalueLoss,
    Objective,
    UntriedTerm,
    approach_activation,
)
from bve_mj.planning.plan import PlanStatus, ViewPlan
from bve_mj.planning.size_information import SizeInformation
from bve_mj.planning.solve import feasible_start, minimise

__all__ = ["SEED_DIRECTIONS", "BvePlanner"]

# The optimiser stops on absolute changes of the objective: the max-eigenvalue loss is in
# m² (~1e-4), so it is handed to the optimiser in mm². A positive constant factor moves no
# minimiser.
_LOSS_SCALE: dict[str, float] = {"dispersion": 1.0, "max_eigenvalue": 1e6}

SEED_DIRECTIONS = np.array(
    [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]]
    + [[a, b, c] for a in (-1, 1) for b in (-1, 1) for c in (-1, 1)],
    dtype=float,
)
SEED_DIRECTIONS /= np.linalg.norm(SEED_DIRECTIONS, axis=1, keepdims=True)


@dataclass
class BvePlanner:
    """BVE planner (paper section 2.1) over the task constraints ``constraint_names``."""

    settings: Settings
    loss: LossName
    constraint_names: Sequence[ConstraintName]
    extra_constraints: ExtraConstraints | None = None
    info: ObservationInformation = field(init=False)
    _views_precision: np.ndarray | None = field(init=False, default=None)
    _failed: list[np.ndarray] = field(init=False, default_factory=list)
    _fused: list[np.ndarray] = field(init=False, default_factory=list)
    _fused_at: list[np.ndarray] = field(init=False, default_factory=list)  # their cameras [m]

    def __post_init__(self) -> None:
        self.constraint_names = check_constraint_names(self.constraint_names)
        if self.loss not in _LOSS_SCALE:
            from bve_mj.errors import ConfigError

            raise ConfigError("loss", self.loss, "one of " + ", ".join(_LOSS_SCALE))
        self.info = observation_information(self.settings)

    def prior_precision(self, belief: Belief) -> np.ndarray:
        """Σo⁻¹: the EKF's P⁻¹, or P0⁻¹ plus Λn of every view planned so far (eq. 9)."""
        if self.settings.prior_source == "filter":
            return belief.precision()
        if self._views_precision is None:
            self._views_precision = belief.precision()
        return self._views_precision

    def note_failed_view(self, p_world_camera: np.ndarray, p_world_target: np.ndarray) -> None:
        """The view from ``p_world_camera`` of the estimate ``p_world_target`` measured
        nothing: later plans expect little of views near it (``failed_view_width_deg``)."""
        d = np.asarray(p_world_camera, dtype=float) - np.asarray(p_world_target, dtype=float)
        n = float(np.linalg.norm(d))
        if self.settings.planner.failed_view_width_deg > 0.0 and np.isfinite(n) and n > 1e-9:
            self._failed.append(d / n)

    def note_fused_view(
        self, p_world_camera: np.ndarray, p_world_target: np.ndarray, *, restart: bool = False
    ) -> None:
        """The filter fused the view from ``p_world_camera`` of the estimate
        ``p_world_target`` (``restart``: the first after a belief reset): with a noise model
        whose views' errors correlate, later plans expect less of views near it
        (:class:`SizeInformation` ``taken``)."""
        if restart:
            self._fused.clear()
            self._fused_at.clear()
        d = np.asarray(p_world_camera, dtype=float) - np.asarray(p_world_target, dtype=float)
        n = float(np.linalg.norm(d))
        if isinstance(self.info, SizeInformation) and np.isfinite(n) and n > 1e-9:
            self._fused.append(d / n)
            self._fused_at.append(np.asarray(p_world_camera, dtype=float).copy())

    def information_model(self) -> ObservationInformation:
        """Λn(c) as the objective sees it: each view as the share of a fresh one it adds
        beside the views fused, discounted near the views that failed."""
        info = self.info
        if self._fused and isinstance(info, SizeInformation):
            info = dataclasses.replace(info, taken=np.array(self._fused), taken_at=np.array(self._fused_at))
        if not self._failed:
            return info
        width = math.radians(self.settings.planner.failed_view_width_deg)
        return FailedViewDiscount(info, np.array(self._failed), width)

    def objective(
        self, belief: Belief, iteration: int, extra_precision: np.ndarray | None = None
    ) -> Objective:
        """The BVE objective F(c) for this belief and iteration (eqs. 10-13); with
        ``extra_precision``, the views planned after this one (:meth:`lookahead`) count as
        already fused."""
        x_hat = belief.mean
        Lo = self.prior_precision(belief)
        if extra_precision is not None:
            Lo = Lo + extra_precision
        p = self.settings.planner
        info = self.information_model()
        terms: list[LossTerm] = [
            DispersionLoss(info, x_hat, Lo)
            if self.loss == "dispersion"
            else MaxEigenvalueLoss(info, x_hat, Lo, p.max_eigenvalue_trace_weight)
        ]
        act = approach_activation(iteration, p.approach_aggressiveness, p.approach_set_point)
        if act > 0.0:
            terms.append(ApproachTerm(belief.centre_m, act))
        if self._failed and p.untried_weight > 0.0:
            terms.append(self._untried(belief.centre_m, Lo))
        return Objective(tuple(terms), _LOSS_SCALE[self.loss])

    def _untried(self, k_hat: np.ndarray, Lo: np.ndarray) -> UntriedTerm:
        """The cost of looking again from where views failed (:class:`UntriedTerm`), in the
        loss's units: ``untried_weight`` nats for the dispersion; for the max-eigenvalue loss
        the share 1 - e^-β of the largest variance without a view."""
        p = self.settings.planner
        weight = p.untried_weight
        if self.loss != "dispersion":
            weight = -math.expm1(-weight) * float(np.linalg.eigvalsh(la.inv(Lo)[:3, :3])[-1])
        return UntriedTerm(k_hat, np.array(self._failed), math.radians(p.failed_view_width_deg), weight)

    def task_constraints(self, k_hat: np.ndarray) -> list[Constraint]:
        """Every task constraint around the estimate (the step limit is added in plan)."""
        return build_constraints(self.constraint_names, self.settings, k_hat, self.extra_constraints)

    def plan(self, belief: Belief, p_world_camera: np.ndarray, iteration: int) -> ViewPlan:
        """:meth:`propose` a viewpoint, then :meth:`commit` it."""
        plan = self.propose(belief, p_world_camera, iteration)
        self.commit(plan, belief)
        return plan

    def commit(self, plan: ViewPlan, belief: Belief) -> None:
        """Record that the camera goes to ``plan``: with ``prior_source = views`` its Σn at the
        estimate ``belief`` is fused into Σo (eq. 9)."""
        if self._views_precision is not None:
            x_hat = np.concatenate([plan.p_world_target, belief.mean[3:]])
            # the radius-state model: as the objective expects the view (its share beside the
            # views fused, the odds it detects): a camera that holds adds almost nothing to Σo
            info = self.information_model() if isinstance(self.info, SizeInformation) else self.info
            self._views_precision = self._views_precision + info.information(plan.p_world_camera, x_hat)

    def propose(self, belief: Belief, p_world_camera: np.ndarray, iteration: int) -> ViewPlan:
        """The best viewpoint for this belief, without changing the planner's state: the
        greedy BVE's, or with ``planner.horizon`` > 1 the first of the best H views."""
        t0 = time.perf_counter()
        plan = self._greedy(
            belief, np.asarray(p_world_camera, dtype=float), iteration, self.objective(belief, iteration)
        )
        if self.settings.planner.horizon > 1 and plan.feasible:
            ahead = self.plan_ahead(
                belief, np.asarray(p_world_camera, dtype=float), iteration, plan.p_world_camera
            )
            if ahead is not None:
                plan = dataclasses.replace(
                    plan, p_world_camera=ahead[0], loss=self.objective(belief, iteration).value(ahead[0])
                )
        return dataclasses.replace(plan, plan_s=time.perf_counter() - t0)

    def plan_ahead(
        self, belief: Belief, c_now: np.ndarray, iteration: int, first: np.ndarray
    ) -> np.ndarray | None:
        """The best ``planner.horizon`` views (H, 3) from ``c_now`` for this belief, started from
        the greedy roll-out whose first view is ``first`` (see :mod:`bve_mj.planning.horizon`);
        None when the approach term is on (it rewards the last view, not the path) or no
        feasible roll-out exists."""
        p = self.settings.planner
        if approach_activation(iteration, p.approach_aggressiveness, p.approach_set_point) > 0.0:
            return None
        H, r = p.horizon, self.settings.step_m
        info = self.information_model()
        x_hat = belief.mean
        Lo = self.prior_precision(belief)
        views = [np.asarray(first, dtype=float)]
        extra = info.information(views[0], x_hat)
        for h in range(1, H):  # the greedy roll-out: each view the best given those before it
            nxt = self._greedy(belief, views[-1], iteration + h, self.objective(belief, iteration + h, extra))
            if not nxt.feasible:
                return None
            views.append(nxt.p_world_camera)
            extra = extra + info.information(nxt.p_world_camera, x_hat)
        task = self.task_constraints(belief.centre_m)
        every: list[Constraint] = [*task, StepLimit(c_now, r)]
        cons = horizon_constraints(every, H, r)
        objective = HorizonObjective(
            info, x_hat, Lo, self.loss, p.max_eigenvalue_trace_weight, _LOSS_SCALE[self.loss]
        )
        z0 = np.concatenate(views)
        res = minimise(objective.value_and_gradient, cons, z0, p.optimiser, p.max_iterations)
        if (
            np.all(np.isfinite(res.x))
            and max_violation(cons, res.x) <= p.feasibility_tol
            and objective.value(res.x) <= objective.value(z0)
        ):
            return res.x.reshape(H, 3)
        return z0.reshape(H, 3)

    def lookahead(self, belief: Belief, c_now: np.ndarray, iteration: int) -> np.ndarray | None:
        """The precision the views after the first of a ``planner.horizon`` plan would add (a
        planner that solves the first view its own way, the arm's in joint space, counts them
        as fused); None with no horizon or no feasible plan."""
        if self.settings.planner.horizon <= 1:
            return None
        first = self._greedy(
            belief, np.asarray(c_now, dtype=float), iteration, self.objective(belief, iteration)
        )
        if not first.feasible:
            return None
        ahead = self.plan_ahead(belief, c_now, iteration, first.p_world_camera)
        if ahead is None:
            return None
        info = self.information_model()
        return sum((info.information(c, belief.mean) for c in ahead[1:]), np.zeros_like(belief.cov))

    def _greedy(self, belief: Belief, c_now: np.ndarray, iteration: int, objective: Objective) -> ViewPlan:
        """The greedy BVE: the best single view from ``c_now`` under ``objective``."""
        t0 = time.perf_counter()
        p = self.settings.planner
        tol = p.feasibility_tol
        k_hat = belief.centre_m
        task = self.task_constraints(k_hat)
        step = StepLimit(c_now, self.settings.step_m)
        x_start, ok = feasible_start(task, step, c_now, tol)

        loss = objective.value
        if not ok:
            return ViewPlan(
                x_start, k_hat, "restoring", False, max_violation(task, x_start), loss(x_start),
                0, time.perf_counter() - t0,
            )  # fmt: skip
        every: list[Constraint] = [*task, step]
        candidates = [x_start, *(c_now + 0.9 * step.step_m * SEED_DIRECTIONS)]
        scored = sorted((loss(x), i, x) for i, x in enumerate(candidates) if max_violation(every, x) <= tol)
        best_f, _, best_x = scored[0]
        status: PlanStatus = "best_feasible"
        iterations = 0
        for f0, _, x0 in scored[: p.starts]:
            res = minimise(
                objective.value_and_gradient, every, x0, p.optimiser, p.max_iterations, objective.lazy
            )
            iterations += res.nit
            f_res = res.fun / objective.scale
            if not (np.all(np.isfinite(res.x)) and max_violation(every, res.x) <= tol and f_res <= f0):
                continue
            if f_res < best_f or status == "best_feasible":
                if f_res <= best_f:
                    best_f, best_x = f_res, res.x
                status = "optimal" if res.success else status
        return ViewPlan(
            best_x, k_hat, status, True, max_violation(every, best_x), best_f, iterations,
            time.perf_counter() - t0,
        )  # fmt: skip
