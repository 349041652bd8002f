"""The baselines for every fruit of a truss: one single-target baseline planner (random,
circle, three fixed views) under the same constraints and the arm's reachability, aimed at
the centre of the fruit found so far, blind to their information (the BVE's views for every
fruit: :mod:`bve_mj.planning.every_fruit`)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from bve_mj.errors import BveError
from bve_mj.estimation.belief import Belief
from bve_mj.planning.every_fruit import EXPLORE, FruitTarget
from bve_mj.planning.plan import Planner, SyncsToEncoders, ViewPlan

__all__ = ["PatternPlanner"]


@dataclass
class PatternPlanner:
    """A baseline for every fruit: one single-target baseline planner (random, circle, fixed
    views) aimed at the centre of the fruit found so far, blind to their information.

    Args:
        planner: the single-target baseline (with the arm's reachability).
        zone: the work zone's belief: its centre is the aim before any fruit is tracked, its
            covariance the belief every plan is made for.
    """

    planner: Planner
    zone: Belief
    _aimed: Belief | None = field(default=None, init=False, repr=False)

    def _aim(self, fruits: Sequence[FruitTarget]) -> Belief:
        if not fruits:
            return self.zone
        centre = np.mean([f.belief.centre_m for f in fruits], axis=0)
        return Belief(np.r_[centre, self.zone.mean[3:]], self.zone.cov)

    def _plan(self, aim: Belief, p_world_camera: np.ndarray, iteration: int) -> ViewPlan:
        plan = self.planner.plan(aim, p_world_camera, iteration)
        if not (np.all(np.isfinite(plan.p_world_camera)) and np.all(np.isfinite(plan.p_world_target))):
            raise BveError("the baseline's viewpoint is not finite")
        return plan

    def plan(
        self,
        fruits: Sequence[FruitTarget],
        p_world_camera: np.ndarray,
        iteration: int,
        q: np.ndarray | None = None,
    ) -> tuple[ViewPlan, int]:
        """The baseline's next viewpoint, planned for no fruit (:data:`EXPLORE`)."""
        self._aimed = self._aim(fruits)
        return self._plan(self._aimed, p_world_camera, iteration), EXPLORE

    def explore(
        self, zone: Belief, p_world_camera: np.ndarray, iteration: int, q: np.ndarray | None = None
    ) -> ViewPlan:
        """The baseline's next viewpoint (it explores as it plans, aimed where it last was)."""
        return self._plan(self._aimed or zone, p_world_camera, iteration)

    def forget(self, fruit: int) -> None:
        """Nothing to forget: the baseline keeps no per-fruit state."""

    def set_configuration(self, q: np.ndarray) -> None:
        if isinstance(self.planner, SyncsToEncoders):
            self.planner.set_configuration(q)

    def note_failed_view(self, fruit: int, p_world_camera: np.ndarray, p_world_target: np.ndarray) -> None:
        """Ignored: the baseline does not learn from views."""

    def note_fused_view(self, fruit: int, p_world_camera: np.ndarray, p_world_target: np.ndarray) -> None:
        """Ignored: the baseline does not learn from views."""

    def note_explored(self, p_world_camera: np.ndarray, p_world_target: np.ndarray) -> None:
        """Ignored: the baseline does not learn from views."""
