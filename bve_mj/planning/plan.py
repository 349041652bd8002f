"""The planner interface and its result record."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, Protocol, runtime_checkable

import numpy as np

from bve_mj.estimation.belief import Belief

__all__ = [
    "LearnsFromFailedViews",
    "LearnsFromFusedViews",
    "PlanStatus",
    "Planner",
    "PlannerAround",
    "SyncsToEncoders",
    "ViewPlan",
]

PlanStatus = Literal["optimal", "best_feasible", "restoring", "fallback"]
"""optimal: the optimiser converged on a feasible point. best_feasible: it did not converge
(or left the feasible set) and the best feasible point found is returned. restoring: no
point within the step limit satisfies the task constraints; the returned point is the one
that violates them least (it always satisfies the step limit). fallback: the planner
failed (raised, or returned a non-finite point); the episode loop holds the camera where it
is, looking at the estimate."""


@dataclass(frozen=True)
class ViewPlan:
    """The next viewpoint.

    Attributes:
        p_world_camera: next camera position [m], (3,).
        p_world_target: the point the camera looks at (the estimate when planned) [m], (3,).
        status: see :data:`PlanStatus`.
        feasible: every task constraint holds (to the planner's tolerance).
        max_violation: largest constraint value at the returned point (0 if feasible).
        loss: the objective at the returned point (NaN for baselines).
        iterations: optimiser iterations spent.
        plan_s: wall time of the plan [s].
        q: joint configuration that realises the viewpoint, when an arm is planned for.
    """

    p_world_camera: np.ndarray
    p_world_target: np.ndarray
    status: PlanStatus
    feasible: bool
    max_violation: float
    loss: float = float("nan")
    iterations: int = 0
    plan_s: float = 0.0
    q: np.ndarray | None = None


class Planner(Protocol):
    """Chooses the next camera position from the belief and the current camera position.

    A planner for an arm may also offer ``set_configuration(q)``: the episode loop then
    tells it the joint angles the encoders measured after each move (the arm may not be
    where the last plan put it: tracking error, a failed IK, a fallback).
    """

    def plan(self, belief: Belief, p_world_camera: np.ndarray, iteration: int) -> ViewPlan:
        """The next viewpoint; ``iteration`` counts planned views from 1."""
        ...


@runtime_checkable
class LearnsFromFailedViews(Protocol):
    """A planner the episode loop tells of each view that measured nothing (or nothing the
    filter accepted), so that it stops proposing views that cannot be used."""

    def note_failed_view(self, p_world_camera: np.ndarray, p_world_target: np.ndarray) -> None:
        """The camera at ``p_world_camera``, looking at the estimate ``p_world_target``, got
        no usable measurement."""
        ...


@runtime_checkable
class LearnsFromFusedViews(Protocol):
    """A planner the episode loop tells of each view the filter fused, so that it can expect
    less of views that would repeat one (their errors are shared)."""

    def note_fused_view(
        self, p_world_camera: np.ndarray, p_world_target: np.ndarray, *, restart: bool = False
    ) -> None:
        """The filter fused the view from ``p_world_camera`` of the estimate ``p_world_target``
        (``restart``: after a belief reset, which forgot the views fused before it)."""
        ...


@runtime_checkable
class SyncsToEncoders(Protocol):
    """A planner for an arm that plans the next move from the joint angles the encoders read
    (not from where its last plan put the arm)."""

    def set_configuration(self, q: np.ndarray) -> None:
        """Plan the next move from ``q`` [rad]."""
        ...


class PlannerAround:
    """A planner around ``planner``: it plans with it and passes on what the loop tells it
    (the encoders' joint angles, the views that failed and were fused) where ``planner``
    takes them. Subclasses change :meth:`plan` (injected faults, a clearance check)."""

    def __init__(self, planner: Planner) -> None:
        self.planner = planner

    def plan(self, belief: Belief, p_world_camera: np.ndarray, iteration: int) -> ViewPlan:
        return self.planner.plan(belief, p_world_camera, iteration)

    def set_configuration(self, q: np.ndarray) -> None:
        if isinstance(self.planner, SyncsToEncoders):
            self.planner.set_configuration(q)

    def note_failed_view(self, p_world_camera: np.ndarray, p_world_target: np.ndarray) -> None:
        if isinstance(self.planner, LearnsFromFailedViews):
            self.planner.note_failed_view(p_world_camera, p_world_target)

    def note_fused_view(
        self, p_world_camera: np.ndarray, p_world_target: np.ndarray, *, restart: bool = False
    ) -> None:
        if isinstance(self.planner, LearnsFromFusedViews):
            self.planner.note_fused_view(p_world_camera, p_world_target, restart=restart)
