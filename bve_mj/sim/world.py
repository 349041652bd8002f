"""The world interface the episode loop talks to, and the records it exchanges."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np

from bve_mj.estimation.belief import Belief
from bve_mj.estimation.models import BearingSizeModel, MeasurementModel
from bve_mj.estimation.noise import Outline
from bve_mj.estimation.tracks import Sighting
from bve_mj.planning.plan import ViewPlan

__all__ = [
    "HoldsOnFailedMove",
    "Observation",
    "ReadsEncoders",
    "ReportsUnmeasured",
    "ReportsViews",
    "Scenario",
    "SeesEveryFruit",
    "SimulatedWorld",
    "World",
]


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
    """A measurement z of ``model`` taken from the camera's current pose; ``outline``: what
    the detector saw of the fruit's outline, where the world knows (a detector's, not a
    synthetic world's); ``sensor_cov``: the part of the model's noise covariance the declared
    sensor errors make (encoder noise), None where none (:mod:`bve_mj.estimation.sensor_share`)."""

    z: np.ndarray
    model: MeasurementModel
    outline: Outline | None = None
    sensor_cov: np.ndarray | None = None


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


@runtime_checkable
class ReportsViews(Protocol):
    """A world that tells what happened in the last view beyond the measurement (an arm's
    joint angles, timings, detector events, injected faults): the episode records it."""

    def view_info(self) -> dict[str, Any]:
        """The last view, JSON-ready; ``events``/``faults`` (lists of text) and ``ik_failed``
        (bool) are read by the loop."""
        ...


@runtime_checkable
class ReadsEncoders(Protocol):
    """A world with an arm whose joint angles are measured: the loop passes them to a planner
    that plans the next move from them (:class:`~bve_mj.planning.plan.SyncsToEncoders`)."""

    @property
    def q_measured(self) -> np.ndarray | None:
        """The joint angles the encoders read at the last view [rad] (None before one)."""
        ...


@runtime_checkable
class HoldsOnFailedMove(Protocol):
    """A world whose arm can be told that a move failed (its IK): it holds where it is."""

    def hold(self, plan: ViewPlan) -> None:
        """The move to ``plan`` failed: stay, with ``plan`` as the next target."""
        ...


class SimulatedWorld(World, Protocol):
    """A world that knows the truth (the synthetic and the MuJoCo worlds): what a fault
    injector needs to fake a detection of something else."""

    @property
    def p_world_fruit(self) -> np.ndarray:
        """The true fruit centre [m], (3,)."""
        ...


class SeesEveryFruit(Protocol):
    """A world that measures every ripe fruit in view (the multi-fruit loop's world): an arm
    with a camera, whose views report what happened."""

    @property
    def p_world_camera(self) -> np.ndarray:
        """Current camera position [m], (3,), as the encoders report it."""
        ...

    @property
    def q_measured(self) -> np.ndarray | None:
        """The joint angles the encoders read at the last view [rad] (None before one)."""
        ...

    def move_camera(self, plan: ViewPlan) -> None:
        """Drive the camera to the plan's viewpoint, looking at its target."""
        ...

    def observe_all(self) -> tuple[list[Sighting], BearingSizeModel]:
        """Every ripe fruit measured from the current pose, and a model at this view's camera
        pose (its noise unused: for what the tracks predict the camera sees)."""
        ...

    def view_info(self) -> dict[str, Any]:
        """The last view, JSON-ready."""
        ...


@runtime_checkable
class ReportsUnmeasured(Protocol):
    """A world whose every-fruit views also report the fruit its detector found but could not
    measure (seen only in part: :mod:`bve_mj.estimation.unmeasured`)."""

    def unmeasured(self) -> list[Sighting]:
        """The weak sightings of the fruit the last :meth:`SeesEveryFruit.observe_all` saw in
        part, in the same camera pose as its sightings."""
        ...
