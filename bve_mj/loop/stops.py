"""When an episode ends: the stop rules, and whether its final estimate rests on the views."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from bve_mj.estimation import Belief
from bve_mj.estimation.metrics import chi2_quantile
from bve_mj.geometry import unit
from bve_mj.loop.outcomes import Outcome
from bve_mj.loop.records import ViewRecord, since_reset

if TYPE_CHECKING:
    from bve_mj.config import EpisodeConfig

__all__ = ["SETTLE_DEG", "StopRules", "accepted_since_reset", "supported"]

SETTLE_DEG = 30.0
"""A view this far (or farther) in direction from another, seen from the fruit, is an
independent witness of it: the detector's errors of two views correlate by 0.4-0.6 within 5°,
0.15-0.25 at 10-15° and not at all beyond 30° (:mod:`bve_mj.estimation.view_correlation`)."""


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
        agree_nis: when set, "converged" and "stable" also need no dispute standing: after
            the last accepted measurement since the last reset (its first excepted: that one
            is tested only against the prior) whose NIS exceeded this (the 99.9% χ² quantile of
            the measurement's dimension), ``agree_views`` accepted views from directions at
            least :data:`SETTLE_DEG` away from it (:meth:`standing_dispute`). A view that
            disputes the belief says one of the two is off by more than the noise model
            allows, and only a view whose error is independent of it settles which (seen in
            ``truss_cluster``, seed 3976831502: a side view and views from above disagreed at
            NIS 24; the next view from above agreed with the first, and the episode claimed
            σmax 0.9 mm 4.3 mm off).
        agree_views: see ``agree_nis``.
        approach_distance_m: the camera is this close to the estimate ("approached").
        stall_m: the camera moved less than this over ``stable_views`` views, each planned
            and reached (a fallback or an IK failure does not count): the planner finds no
            better view it can reach, and more views from one place would only fuse
            the same errors again (a per-fruit bias such as the unknown radius is not averaged
            out by repeating it). "approach_blocked" in approach mode (it cannot come closer),
            where a camera held by failed plans counts too, else "stalled".
        redundant: "converged" also needs every claim the episode would make with one of its
            accepted measurements since the last reset left out (the others fused again from
            the prior) to have σmax within ``sigma_m``: the answer does not rest on any single
            view (the integrity check of satellite navigation, solution separation: each
            subset that drops one measurement must meet the requirement too). A view's error
            that nothing else measures is not checked by anything (seen in ``truss_cluster``,
            episode 2273102041: a view from 37° above, its fit 6 px off along a neighbour's
            edge, and two views from one place below it; converged 9.0 mm off claiming σmax
            0.77 mm: without the view from above the claim was 5.1 mm wide, without either of
            the others 3.0 and 0.77).
        stall_escapes: how many times :func:`~bve_mj.loop.episode.run_episode` goes on past a
            stall (not in approach mode), the planner told that the view the camera holds at is
            spent (a planner that learns from failed views then looks elsewhere): the planner's
            optimum near the camera only repeats that view's errors, and a view from another
            direction adds what they lack (the size-only measurement in trusses, where most
            episodes stalled within a few millimetres of one spot).
    """

    sigma_m: float | None = None
    min_accepted: int = 1
    stable_m: float | None = None
    stable_views: int = 3
    approach_distance_m: float | None = None
    stall_m: float | None = None
    agree_nis: float | None = None
    agree_views: int = 1
    stall_escapes: int = 0
    redundant: bool = False

    def outcome(
        self, views: list[ViewRecord], leave_one_out: Callable[[], Sequence[Belief]] | None = None
    ) -> Outcome | None:
        """The rule that ends the episode after ``views``, or None: it goes on.
        ``leave_one_out``: the claims with each accepted measurement left out in turn
        (:meth:`~bve_mj.loop.episode.EpisodeLoop.leave_one_out`), asked for only when
        ``redundant`` and every other condition of "converged" holds."""
        b = views[-1].belief
        n = self.stable_views
        held = (
            self.stall_m is not None
            and len(views) > n
            and max(
                np.linalg.norm(views[-i].p_world_camera - views[-n - 1].p_world_camera)
                for i in range(1, n + 1)
            )
            < self.stall_m
        )
        stalled = held and all(_planned_move(v) for v in views[-n:])
        if self.approach_distance_m is not None:
            if np.linalg.norm(views[-1].p_world_camera - b.centre_m) <= self.approach_distance_m:
                return Outcome.APPROACHED
            # held by the planner's failures too: every move it tried closer passed into the
            # fruit or the canopy (the default approach, seed 2, held 0.124 m away 9 views)
            return Outcome.APPROACH_BLOCKED if held else None
        if (
            self.sigma_m is not None
            and b.sigma_max_m <= self.sigma_m
            and accepted_since_reset(views) >= self.min_accepted
            and self.standing_dispute(views) is None
            and (
                not self.redundant
                or leave_one_out is None
                or all(c.sigma_max_m <= self.sigma_m for c in leave_one_out())
            )
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
            if max(moves) <= self.stable_m and apart and self.standing_dispute(views) is None:
                return Outcome.STABLE
        return Outcome.STALLED if stalled else None

    @classmethod
    def for_episode(cls, episode: EpisodeConfig, measurement_kind: str) -> StopRules:
        """The closed loop's rules from its settings: approach mode's, or the localising ones
        (a dispute's NIS limit the 99.9% χ² quantile of the measurement's dimension: the
        apparent size alone for ``range``, bearing and size otherwise)."""
        if episode.approach:
            return cls(
                approach_distance_m=episode.approach_distance_m, stall_m=episode.stall_m,
                stable_views=episode.stable_views,
            )  # fmt: skip
        dimension = 1 if measurement_kind == "range" else 3
        return cls(
            sigma_m=episode.stop_sigma_m,
            min_accepted=episode.converge_after,
            stable_m=episode.stop_stable_m,
            stable_views=episode.stable_views,
            stall_m=episode.stall_m,
            agree_nis=float(chi2_quantile(0.999, dimension)) if episode.agree_views else None,
            agree_views=max(episode.agree_views, 1),
            stall_escapes=episode.stall_escapes,
            redundant=episode.converge_redundant,
        )

    def standing_dispute(self, views: Sequence[ViewRecord]) -> ViewRecord | None:
        """The last view since the last reset (its first accepted one excepted) whose accepted
        measurement disputed the belief (NIS above ``agree_nis``), unless ``agree_views``
        accepted views after it, from directions at least :data:`SETTLE_DEG` away from it
        (seen from the estimate), agreed; None when no dispute stands (or ``agree_nis`` is
        unset)."""
        if self.agree_nis is None:
            return None
        fused = [v for v in since_reset(views) if v.accepted][1:]
        disputes = [k for k, v in enumerate(fused) if v.nis > self.agree_nis]
        if not disputes:
            return None
        centre = views[-1].belief.centre_m
        disputed = fused[disputes[-1]]
        d0 = unit(disputed.p_world_camera - centre)
        cos_limit = math.cos(math.radians(SETTLE_DEG))
        after = fused[disputes[-1] + 1 :]
        settling = [v for v in after if unit(v.p_world_camera - centre) @ d0 <= cos_limit]
        return None if len(settling) >= self.agree_views else disputed


def accepted_since_reset(views: Sequence[ViewRecord]) -> int:
    """Accepted measurements since the last belief reset (the reset's own view counts)."""
    return sum(v.accepted for v in since_reset(views))


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
