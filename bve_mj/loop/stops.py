"""When an episode ends: the stop rules, and whether its final estimate rests on the views."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from bve_mj.loop.outcomes import Outcome
from bve_mj.loop.records import ViewRecord

__all__ = ["StopRules", "accepted_since_reset", "supported"]


@dataclass(frozen=True)
class StopRules:
    """When an episode ends before its last view.

    Attributes:
        sigma_m: the largest posterior standard deviation falls below this ("converged"), with
            at least ``min_accepted`` accepted measurements since the last belief reset.
        stable_m: the estimate moves less than this over ``stable_views`` views, each with an
            accepted measurement ("stable"; a gated-out view does not count as agreement) and,
            when ``stall_m`` is set, each taken at least ``stall_m`` from the view before: a
            view from the same place repeats that view's error (the apparent size's bias in
            range-only episodes: seen in ``truss_cluster``, held still by three views within
            8 mm of each other, 11.8 mm off claiming σmax 8.7 mm), so it shows nothing about
            whether the estimate is stable.
        approach_distance_m: the camera is this close to the estimate ("approached").
        stall_m: the camera moved less than this over ``stable_views`` views, each planned
            and reached (a fallback or an IK failure does not count): the planner finds no
            better view it can reach, and more views from one place would only fuse
            the same errors again (a per-fruit bias such as the unknown radius is not averaged
            out by repeating it). "approach_blocked" in approach mode (it cannot come closer),
            else "stalled".
    """

    sigma_m: float | None = None
    min_accepted: int = 1
    stable_m: float | None = None
    stable_views: int = 3
    approach_distance_m: float | None = None
    stall_m: float | None = None

    def outcome(self, views: list[ViewRecord]) -> Outcome | None:
        b = views[-1].belief
        n = self.stable_views
        stalled = (
            self.stall_m is not None
            and len(views) > n
            and all(_planned_move(v) for v in views[-n:])
            and max(
                np.linalg.norm(views[-i].p_world_camera - views[-n - 1].p_world_camera)
                for i in range(1, n + 1)
            )
            < self.stall_m
        )
        if self.approach_distance_m is not None:
            if np.linalg.norm(views[-1].p_world_camera - b.centre_m) <= self.approach_distance_m:
                return Outcome.APPROACHED
            return Outcome.APPROACH_BLOCKED if stalled else None
        if (
            self.sigma_m is not None
            and b.sigma_max_m <= self.sigma_m
            and accepted_since_reset(views) >= self.min_accepted
        ):
            return Outcome.CONVERGED
        if self.stable_m is not None and len(views) > n and all(v.accepted for v in views[-n:]):
            moves = [
                np.linalg.norm(views[-i].belief.centre_m - views[-i - 1].belief.centre_m)
                for i in range(1, n + 1)
            ]
            apart = self.stall_m is None or all(
                np.linalg.norm(views[-i].p_world_camera - views[-i - 1].p_world_camera) >= self.stall_m
                for i in range(1, n + 1)
            )
            if max(moves) <= self.stable_m and apart:
                return Outcome.STABLE
        return Outcome.STALLED if stalled else None


def accepted_since_reset(views: Sequence[ViewRecord]) -> int:
    """Accepted measurements since the last belief reset (the reset's own view counts)."""
    start = max((k for k, v in enumerate(views) if v.has("belief_reset")), default=0)
    return sum(v.accepted for v in views[start:])


def _planned_move(view: ViewRecord) -> bool:
    """The planner chose this view and the arm went there: no planner fallback, no IK failure
    (a camera held by a failure has not run out of better views)."""
    return view.plan_status != "fallback" and not (view.has("ik_failed") or view.has("ik_failure"))


def supported(views: Sequence[ViewRecord], window: int) -> bool:
    """Whether the final estimate rests on the measurements: at least two accepted since the
    last belief reset, and at most half of the last ``2 * window`` measurements gated out
    (when most recent measurements disagree with the estimate, the estimate is not what the
    camera sees). An episode that fails this ends ``unreliable`` whatever its stop rule said."""
    if accepted_since_reset(views) < 2:
        return False
    recent = [v for v in views if v.measured][-2 * window :]
    return 2 * sum(not v.accepted for v in recent) <= len(recent)
