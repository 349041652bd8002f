"""The episode loop: observe → fuse → plan → move, the same in every world."""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from bve_mj.config import FilterConfig
from bve_mj.estimation.belief import Belief
from bve_mj.estimation.ekf import predict, update
from bve_mj.planning.plan import Planner, PlanStatus
from bve_mj.sim.world import World

__all__ = ["EpisodeResult", "ViewRecord", "run_episode"]


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


@dataclass(frozen=True)
class EpisodeResult:
    """A finished episode: the prior, every view, the final belief, and the wall time [s]."""

    prior: Belief
    views: tuple[ViewRecord, ...]
    wall_s: float

    @property
    def final(self) -> Belief:
        return self.views[-1].belief if self.views else self.prior


def run_episode(
    world: World,
    planner: Planner,
    prior: Belief,
    filter_config: FilterConfig,
    steps: int,
) -> EpisodeResult:
    """Observe from the start pose, then ``steps`` times: plan, move, predict, observe, update."""
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
        views.append(
            ViewRecord(i, world.p_world_camera, status, feasible, plan_s, measured, accepted, nis, belief)
        )

    fuse(0, None, True, 0.0)
    for i in range(1, steps + 1):
        plan = planner.plan(belief, world.p_world_camera, i)
        world.move_camera(plan)
        belief = predict(belief, Q)
        fuse(i, plan.status, plan.feasible, plan.plan_s)
    return EpisodeResult(prior, tuple(views), time.perf_counter() - t0)
