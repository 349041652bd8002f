"""The world interface the episode loop talks to, and the records it exchanges."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from bve_mj.estimation.belief import Belief
from bve_mj.estimation.models import MeasurementModel
from bve_mj.planning.plan import ViewPlan

__all__ = ["Observation", "Scenario", "World"]


@dataclass(frozen=True)
class Scenario:
    """One run's ground truth and starting point [m].

    Attributes:
        p_world_fruit: true fruit centre, (3,).
        p_world_camera_start: camera position at the start, (3,).
        initial_estimate: the filter's prior mean, (3,).
    """

    p_world_fruit: np.ndarray
    p_world_camera_start: np.ndarray
    initial_estimate: np.ndarray


@dataclass(frozen=True)
class Observation:
    """A measurement z of ``model`` taken from the camera's current pose."""

    z: np.ndarray
    model: MeasurementModel


class World(Protocol):
    """Where the camera is, how it moves, and what it measures."""

    @property
    def p_world_camera(self) -> np.ndarray:
        """Current camera position [m], (3,)."""
        ...

    def move_camera(self, plan: ViewPlan) -> None:
        """Drive the camera to the plan's viewpoint, looking at its target."""
        ...

    def observe(self, belief: Belief | None = None) -> Observation | None:
        """Measure the fruit from the current pose; None when nothing is detected.

        ``belief``: the filter's prediction for this view (a world that sees several fruit
        uses it to tell which one is the target)."""
        ...
