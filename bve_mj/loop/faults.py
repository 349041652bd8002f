"""Fault injection: wrappers that make a world or a planner misbehave, seeded.

:class:`FaultyWorld` loses detections (at random or on given views), swaps a measurement
for one of another red object near the fruit, adds gross errors, and makes moves fail as
if the IK had (the arm holds). :class:`FaultyPlanner` makes the optimiser fail (raise).
Every view draws the same random numbers whatever happens, so one fault never shifts the
others. What was injected is logged in the view's ``faults`` list.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from bve_mj.config import FaultConfig
from bve_mj.errors import PlanningError
from bve_mj.estimation.belief import Belief
from bve_mj.planning.plan import Planner, PlannerAround, ViewPlan
from bve_mj.sim.world import (
    HoldsOnFailedMove,
    Observation,
    ReadsEncoders,
    ReportsViews,
    SimulatedWorld,
)

__all__ = ["FaultyPlanner", "FaultyWorld"]


class FaultyWorld:
    """``world`` with the faults of ``faults`` injected from ``rng``."""

    def __init__(self, world: SimulatedWorld, faults: FaultConfig, rng: np.random.Generator) -> None:
        self.world = world
        self.faults = faults
        self._rng = rng
        self._view = 0
        self._events: list[str] = []

    @property
    def p_world_camera(self) -> np.ndarray:
        return self.world.p_world_camera

    @property
    def q_measured(self) -> np.ndarray | None:
        return self.world.q_measured if isinstance(self.world, ReadsEncoders) else None

    def move_camera(self, plan: ViewPlan) -> None:
        self._view += 1
        self._events = []
        if self._rng.random() < self.faults.ik_failure_p:
            self._events.append("ik_failure")
            if isinstance(self.world, HoldsOnFailedMove):
                self.world.hold(plan)
            else:  # a world without an arm: the camera stays, looking at the new target
                self.world.move_camera(
                    dataclasses.replace(plan, p_world_camera=self.world.p_world_camera, q=None)
                )
            return
        self.world.move_camera(plan)

    def observe(self, belief: Belief | None = None) -> Observation | None:
        f = self.faults
        u_drop, u_kind = self._rng.random(2)
        direction = self._rng.standard_normal(3)
        direction /= np.linalg.norm(direction)
        offset_m, sigmas = self._rng.uniform(0.05, 0.30), self._rng.uniform(10.0, 50.0)
        obs = self.world.observe(belief)
        if self._view in f.hidden_views or u_drop < f.drop_p:
            self._events.append("dropped")
            return None
        if obs is None:
            return None
        if u_kind < f.false_p:
            self._events.append("false_detection")
            fake = self.world.p_world_fruit + offset_m * direction
            if belief is not None:  # the state as the filter holds it, with another centre
                fake = np.concatenate([fake, belief.mean[3:]])
            return Observation(np.atleast_1d(obs.model.predict(fake)), obs.model)
        if u_kind < f.false_p + f.outlier_p:
            self._events.append("outlier")
            sd = np.sqrt(np.diag(np.atleast_2d(obs.model.noise_cov)))
            m = sd.shape[0]
            d = direction[:m] / max(float(np.linalg.norm(direction[:m])), 1e-12)
            return Observation(obs.z + sigmas * sd * d, obs.model)
        return obs

    def view_info(self) -> dict[str, Any]:
        info = dict(self.world.view_info()) if isinstance(self.world, ReportsViews) else {}
        info["faults"] = list(self._events)
        return info

    @property
    def p_world_fruit(self) -> np.ndarray:
        return self.world.p_world_fruit


class FaultyPlanner(PlannerAround):
    """``planner`` whose optimiser fails (raises :class:`PlanningError`) with probability ``p``."""

    def __init__(self, planner: Planner, p: float, rng: np.random.Generator) -> None:
        super().__init__(planner)
        self.p = p
        self._rng = rng

    def plan(self, belief: Belief, p_world_camera: np.ndarray, iteration: int) -> ViewPlan:
        if self._rng.random() < self.p:
            raise PlanningError(f"injected optimiser failure at view {iteration}")
        return self.planner.plan(belief, p_world_camera, iteration)
