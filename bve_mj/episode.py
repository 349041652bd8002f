"""The episode loop: observe → fuse → plan → move, the same in every world."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from bve_mj.config import FilterConfig
from bve_mj.estimation.belief import Belief
from bve_mj.estimation.ekf import predict, update
from bve_mj.planning.plan import Planner, PlanStatus
from bve_mj.sim.world import World

__all__ = ["EpisodeResult", "StopRules", "ViewRecord", "run_episode"]


@dataclass(frozen=True)
class ViewRecord:
    """One view: where the camera was, what the planner said, what the filter made of it.

    ``iteration`` 0 is the view from the start pose (no plan: status None).
    """

    iteration: int
    p_world_camera: np.ndarray
    plan_status: PlanStatus | None
    plan_feasible: bool
    plan_s: float
    measured: bool
    accepted: bool
    nis: float
    belief: Belief
    world: dict[str, object] | None = None


@dataclass(frozen=True)
class StopRules:
    """When an episode ends before its last view.

    Attributes:
        sigma_m: the largest posterior standard deviation falls below this ("converged").
        stable_m: the estimate moves less than this over ``stable_views`` views ("stable").
        approach_distance_m: the camera is this close to the estimate ("approached").
    """

    sigma_m: float | None = None
    stable_m: float | None = None
    stable_views: int = 3
    approach_distance_m: float | None = None

    def outcome(self, views: list[ViewRecord]) -> str | None:
        b = views[-1].belief
        if self.approach_distance_m is not None:
            if np.linalg.norm(views[-1].p_world_camera - b.mean) <= self.approach_distance_m:
                return "approached"
            return None  # approach mode ends only by approaching (or running out of views)
        if self.sigma_m is not None and np.sqrt(np.linalg.eigvalsh(b.cov)[-1]) <= self.sigma_m:
            return "converged"
        n = self.stable_views
        if self.stable_m is not None and len(views) > n and all(v.measured for v in views[-n:]):
            moves = [
                np.linalg.norm(views[-i].belief.mean - views[-i - 1].belief.mean) for i in range(1, n + 1)
            ]
            if max(moves) <= self.stable_m:
                return "stable"
        return None


@dataclass(frozen=True)
class EpisodeResult:
    """A finished episode: the prior, every view, the final belief, and the wall time [s]."""

    prior: Belief
    views: tuple[ViewRecord, ...]
    wall_s: float
    outcome: str = "max_views"

    @property
    def final(self) -> Belief:
        return self.views[-1].belief if self.views else self.prior


def run_episode(
    world: World,
    planner: Planner,
    prior: Belief,
    filter_config: FilterConfig,
    steps: int,
    stop: StopRules | None = None,
    on_view: Callable[[ViewRecord], None] | None = None,
) -> EpisodeResult:
    """Observe from the start pose, then up to ``steps`` times: plan, move, predict, observe,
    update; ``stop`` may end it early. Outcome: the rule that ended it, "max_views", or
    "never_detected" when no view measured the fruit."""
    t0 = time.perf_counter()
    Q = np.eye(3) * filter_config.process_sigma_m**2
    gate = filter_config.gate_probability
    belief = prior
    views: list[ViewRecord] = []

    def fuse(i: int, status: PlanStatus | None, feasible: bool, plan_s: float) -> None:
        nonlocal belief
        obs = world.observe()
        measured, accepted, nis = obs is not None, False, float("nan")
        if obs is not None:
            result = update(belief, obs.z, obs.model, gate)
            belief, accepted, nis = result.belief, result.accepted, result.nis
        info = world.view_info() if hasattr(world, "view_info") else None
        views.append(
            ViewRecord(
                i, world.p_world_camera, status, feasible, plan_s, measured, accepted, nis, belief, info
            )
        )
        if on_view is not None:
            on_view(views[-1])

    fuse(0, None, True, 0.0)
    outcome = None
    for i in range(1, steps + 1):
        plan = planner.plan(belief, world.p_world_camera, i)
        world.move_camera(plan)
        belief = predict(belief, Q)
        fuse(i, plan.status, plan.feasible, plan.plan_s)
        outcome = stop.outcome(views) if stop is not None else None
        if outcome is not None:
            break
    if outcome is None:
        outcome = "max_views" if any(v.measured for v in views) else "never_detected"
    return EpisodeResult(prior, tuple(views), time.perf_counter() - t0, outcome)
