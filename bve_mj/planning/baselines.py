"""Baseline planners under the same constraints and step budget as the BVE.

- :class:`RandomPlanner`: a uniformly random feasible point within the step limit.
- :class:`CirclePlanner`: a fixed orbit about the vertical axis through the estimate,
  advancing one step length a view and projected onto the feasible set; it reverses when
  a constraint blocks the orbit.
- :class:`FixedViewsPlanner`: three hand-picked, collinear viewpoints (the protocol of the
  authors' earlier MonoVisual3DFilter: the start view and one either side of it on a
  horizontal line across the view direction, ``constraints.step_m`` apart), visited in turn
  (left, right, centre, left, ...) within the step limit, each looking at the estimate.

Both restore feasibility exactly as the BVE does when no point within reach is feasible.
Constraints marked ``expensive`` (the arm's :class:`~bve_mj.robot.planner.Reachability`, an
IK solve per evaluation) are checked only on points that pass every cheap one: the random
planner tries candidates until one is reachable, the circle planner projects its orbit
point onto the cheap set and then backs off towards the current camera until the arm
reaches it.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from bve_mj.config import Settings
from bve_mj.errors import ConfigError
from bve_mj.estimation.belief import Belief
from bve_mj.planning.constraints import (
    Constraint,
    ConstraintName,
    ExpensiveConstraint,
    ExtraConstraints,
    StepLimit,
    build_constraints,
    check_constraint_names,
    max_violation,
)
from bve_mj.planning.plan import PlanStatus, ViewPlan
from bve_mj.planning.solve import feasible_start, minimise

__all__ = ["CirclePlanner", "FixedViewsPlanner", "RandomPlanner"]


_MAX_EXPENSIVE_CHECKS = 16


def _split(task: Sequence[Constraint]) -> tuple[list[Constraint], list[Constraint]]:
    """(cheap, expensive) constraints (:class:`ExpensiveConstraint` with ``expensive`` true)."""

    def costly(c: Constraint) -> bool:
        return isinstance(c, ExpensiveConstraint) and c.expensive

    return [c for c in task if not costly(c)], [c for c in task if costly(c)]


def _holds(constraints: Sequence[Constraint], x: np.ndarray, tol: float) -> bool:
    """Every constraint holds at x (stops at the first violation)."""
    return all(g.value(x) <= tol for g in constraints)


def _restore_or_none(
    task: Sequence[Constraint],
    step: StepLimit,
    c_now: np.ndarray,
    k_hat: np.ndarray,
    tol: float,
    t0: float,
) -> tuple[ViewPlan | None, np.ndarray]:
    x, ok = feasible_start(task, step, c_now, tol)
    if ok:
        return None, x
    plan = ViewPlan(x, k_hat, "restoring", False, max_violation(task, x), plan_s=time.perf_counter() - t0)
    return plan, x


@dataclass
class RandomPlanner:
    """A random feasible viewpoint within the step limit (rejection sampling in the ball)."""

    settings: Settings
    constraint_names: Sequence[ConstraintName]
    rng: np.random.Generator
    extra_constraints: ExtraConstraints | None = None
    samples: int = 256

    def __post_init__(self) -> None:
        self.constraint_names = check_constraint_names(self.constraint_names)

    def plan(self, belief: Belief, p_world_camera: np.ndarray, iteration: int) -> ViewPlan:
        t0 = time.perf_counter()
        tol = self.settings.planner.feasibility_tol
        k_hat, c_now = belief.centre_m, np.asarray(p_world_camera, dtype=float)
        r_d = self.settings.step_m
        task = build_constraints(self.constraint_names, self.settings, k_hat, self.extra_constraints)
        cheap, expensive = _split(task)
        step = StepLimit(c_now, r_d)
        d = self.rng.standard_normal((self.samples, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        candidates = c_now + d * (r_d * self.rng.random((self.samples, 1)) ** (1.0 / 3.0))
        checks = 0
        for x in candidates:
            if not _holds(cheap, x, tol):
                continue
            if expensive:
                if checks == _MAX_EXPENSIVE_CHECKS:
                    break
                checks += 1
                if not _holds(expensive, x, tol):
                    continue
            return ViewPlan(x, k_hat, "optimal", True, 0.0, plan_s=time.perf_counter() - t0)
        restoring, x = _restore_or_none(cheap, step, c_now, k_hat, tol, t0)
        if expensive and restoring is None and not _holds(expensive, x, tol):
            x = c_now  # nothing reachable found: stay (the arm is there)
        if restoring is not None:
            return restoring
        return ViewPlan(x, k_hat, "best_feasible", True, 0.0, plan_s=time.perf_counter() - t0)


@dataclass
class CirclePlanner:
    """Orbit the estimate about the world z axis, one step length per view."""

    settings: Settings
    constraint_names: Sequence[ConstraintName]
    extra_constraints: ExtraConstraints | None = None
    direction: float = field(default=1.0)

    def __post_init__(self) -> None:
        self.constraint_names = check_constraint_names(self.constraint_names)

    def _orbit_target(self, k_hat: np.ndarray, c_now: np.ndarray) -> np.ndarray:
        r_d = self.settings.step_m
        u = c_now - k_hat
        rho = math.hypot(u[0], u[1])
        if rho < 1e-6:  # directly above or below: start the orbit along +x
            u = u + np.array([r_d, 0.0, 0.0])
            rho = r_d
        angle = self.direction * min(r_d / rho, math.pi / 2)
        ca, sa = math.cos(angle), math.sin(angle)
        v = np.array([ca * u[0] - sa * u[1], sa * u[0] + ca * u[1], u[2]])
        if "band" in self.constraint_names:  # hold the band's middle distance
            v *= self.settings.band_distance_m / float(np.linalg.norm(v))
        return k_hat + v

    def plan(self, belief: Belief, p_world_camera: np.ndarray, iteration: int) -> ViewPlan:
        t0 = time.perf_counter()
        p = self.settings.planner
        tol = p.feasibility_tol
        k_hat, c_now = belief.centre_m, np.asarray(p_world_camera, dtype=float)
        r_d = self.settings.step_m
        task = build_constraints(self.constraint_names, self.settings, k_hat, self.extra_constraints)
        cheap, expensive = _split(task)
        step = StepLimit(c_now, r_d)
        restoring, x_start = _restore_or_none(cheap, step, c_now, k_hat, tol, t0)
        if restoring is not None:
            return restoring
        target = self._orbit_target(k_hat, x_start)
        x, nit, optimal = _towards(target, cheap, expensive, step, x_start, c_now, p.max_iterations, tol)
        if float(np.linalg.norm(x - c_now)) < 0.25 * r_d:
            self.direction = -self.direction  # blocked: go back along the orbit
        status: PlanStatus = "optimal" if optimal else "best_feasible"
        return ViewPlan(x, k_hat, status, True, 0.0, iterations=nit, plan_s=time.perf_counter() - t0)


def _towards(
    target: np.ndarray,
    cheap: Sequence[Constraint],
    expensive: Sequence[Constraint],
    step: StepLimit,
    x_start: np.ndarray,
    c_now: np.ndarray,
    max_iterations: int,
    tol: float,
) -> tuple[np.ndarray, int, bool]:
    """The feasible point within the step limit nearest ``target`` (SLSQP from ``x_start``
    over the cheap constraints; then backed off towards the camera ``c_now`` until the
    expensive ones hold): (point, iterations, whether the optimiser's point was kept)."""

    def distance_sq(x: np.ndarray) -> tuple[float, np.ndarray]:
        d = x - target
        return float(d @ d), 2.0 * d

    every: list[Constraint] = [*cheap, step]
    res = minimise(distance_sq, every, x_start, "slsqp", max_iterations)
    x = res.x if np.all(np.isfinite(res.x)) and max_violation(every, res.x) <= tol else x_start
    if expensive:  # back off towards the current camera until the arm reaches the point
        for _ in range(5):
            if _holds(expensive, x, tol):
                break
            x = 0.5 * (x + c_now)
        else:
            x = c_now
    return x, int(res.nit), x is res.x


@dataclass
class FixedViewsPlanner:
    """Three fixed, collinear viewpoints visited in turn (see the module docstring).

    The line is fixed at the first plan: through the camera then, horizontal, across the
    direction to the estimate then; the views lie ``spacing_m`` (default
    ``constraints.step_m``) either side of the start. A view the constraints (or the arm)
    keep the camera from reaching within ``reached_m`` is given up after one blocked move.
    """

    settings: Settings
    constraint_names: Sequence[ConstraintName]
    extra_constraints: ExtraConstraints | None = None
    spacing_m: float | None = None
    reached_m: float = 0.01
    _views: np.ndarray | None = field(default=None, init=False, repr=False)
    _next: int = field(default=0, init=False, repr=False)

    def __post_init__(self) -> None:
        self.constraint_names = check_constraint_names(self.constraint_names)
        if self.spacing_m is not None and not (math.isfinite(self.spacing_m) and self.spacing_m > 0.0):
            raise ConfigError("spacing_m", self.spacing_m, "a number > 0")

    def views(self, k_hat: np.ndarray, c_start: np.ndarray) -> np.ndarray:
        """The three viewpoints (left, right, centre) for a start camera and estimate (3, 3)."""
        d = np.asarray(c_start, dtype=float) - np.asarray(k_hat, dtype=float)
        across = np.cross(np.array([0.0, 0.0, 1.0]), d)
        n = float(np.linalg.norm(across))
        across = np.array([1.0, 0.0, 0.0]) if n < 1e-9 else across / n
        s = self.settings.step_m if self.spacing_m is None else self.spacing_m
        c = np.asarray(c_start, dtype=float)
        return np.array([c + s * across, c - s * across, c])

    def plan(self, belief: Belief, p_world_camera: np.ndarray, iteration: int) -> ViewPlan:
        t0 = time.perf_counter()
        p = self.settings.planner
        tol = p.feasibility_tol
        k_hat, c_now = belief.centre_m, np.asarray(p_world_camera, dtype=float)
        if self._views is None:
            self._views = self.views(k_hat, c_now)
        task = build_constraints(self.constraint_names, self.settings, k_hat, self.extra_constraints)
        cheap, expensive = _split(task)
        step = StepLimit(c_now, self.settings.step_m)
        restoring, x_start = _restore_or_none(cheap, step, c_now, k_hat, tol, t0)
        if restoring is not None:
            return restoring
        target = self._views[self._next % 3]
        x, nit, optimal = _towards(target, cheap, expensive, step, x_start, c_now, p.max_iterations, tol)
        blocked = float(np.linalg.norm(x - c_now)) < 0.25 * self.settings.step_m
        if float(np.linalg.norm(x - target)) <= self.reached_m or blocked:
            self._next += 1
        status: PlanStatus = "optimal" if optimal else "best_feasible"
        return ViewPlan(x, k_hat, status, True, 0.0, iterations=nit, plan_s=time.perf_counter() - t0)
