"""Pick and look again: the harvest takes each fruit it reaches, and the survey goes on for the
fruit the picked ones hid.

In a cluster the fruit behind the front ones show too little of their outline to be measured
from most views the arm can take (``python benchmarks/bench_coverage_oracle.py --scenario
truss_cluster --episodes 5 --seed 9191 --views 20``: of the 7 ripe fruit the episodes
missed, 3 measured in two or more of 20 reachable views; with ``--picked``, the fruit the
episodes localised taken off, all 7). A picking arm does not need to see them first: it
picks what it knows, and what it uncovers it then sees. With ``tracking.pick_rounds`` = N >
0 (and ``episode.approach``) the harvest picks every fruit its visit reaches
(:func:`picked_fruit`: the true fruit within :data:`PICK_TOLERANCE_M` of the estimate it
went to; a visit to a wrong estimate takes nothing), the fruit and its calyx leave the scene
(:meth:`bve_mj.sim.mujoco_world.MujocoWorld.pick`), its track leaves the tracker (the fruit
is in the basket, not on the plant), and the survey
(:func:`bve_mj.loop.every_fruit.run_every_fruit`, with the tracks it kept, the zone's grid
and the view directions of the surveys before, the grid re-opened within
:data:`LOOK_AGAIN_RADII` of each fruit picked: the scene changed there) runs again, then
another harvest. A survey that another may follow hands over to the harvest once a fruit is
localised and ``episode.converge_after`` + 1 views in a row localise no other while some
fruit is left (:attr:`~bve_mj.loop.every_fruit.SurveyRound.stall_views`): what is hidden
behind the fruit known, picking shows. At most N rounds after the first, ending at a harvest
that picks nothing, or after a survey that ended ``converged`` (every fruit it found
localised, the zone explored and framed, nothing seen in part or dropped: no sign of a fruit
left behind; on the suite's five truss scenes, seeds 9292 and 9393, no survey that ended so
had missed a ripe fruit). Its harvest still picks.

The episode's record joins the rounds: the views in order (numbered on), each later view's
fruit with the picked ones as they were when picked (so "every ripe fruit localised" and the
views it took count the picked ones), the outcome of the last survey, every visit with its
round and the fruit it picked.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

from bve_mj.estimation.tracks import Track, Tracker
from bve_mj.loop.fruit_records import FruitsResult, FruitState
from bve_mj.loop.harvest import HarvestResult, Visit
from bve_mj.loop.outcomes import Outcome
from bve_mj.sim.scene_model import SceneInfo

__all__ = ["LOOK_AGAIN_RADII", "PICK_TOLERANCE_M", "picked_fruit", "survey_and_pick", "take_off"]

PICK_TOLERANCE_M = 0.01
"""A visit picks the fruit whose true centre lies within this of the estimate it went to [m]
(a soft gripper's capture range, about a third of a round tomato's radius)."""

LOOK_AGAIN_RADII = 3.0
"""A survey after a harvest frames anew the part of the zone within this many prior fruit
radii of each fruit picked (a fruit it hid touches it, centres two radii apart, or lies
behind one that did); the rest of the zone was framed before and has not changed."""


def picked_fruit(estimate_m: np.ndarray, info: SceneInfo, gone: tuple[str, ...]) -> str | None:
    """The fruit a visit to ``estimate_m`` picks: the nearest fruit of ``info`` not ``gone``
    whose true centre lies within :data:`PICK_TOLERANCE_M` of it, or None."""
    best: tuple[float, str] | None = None
    for f in info.fruits:
        if f.name in gone:
            continue
        d = float(np.linalg.norm(np.asarray(estimate_m) - f.centre_m))
        if d <= PICK_TOLERANCE_M and (best is None or d < best[0]):
            best = (d, f.name)
    return None if best is None else best[1]


def take_off(tracker: Tracker, seen_in_part: Tracker, track_id: int) -> np.ndarray:
    """A picked fruit leaves the trackers: its track, the fruit seen in part and the tracks
    dropped (deleted unconfirmed) whose centre lies inside it (they were this fruit, now in
    the basket). Returns its centre [m], (3,)."""
    t = tracker.track(track_id)

    def inside(h: Track) -> bool:
        return float(np.linalg.norm(h.centre_m - t.centre_m)) < t.radius_m

    seen_in_part.forget([h for h in seen_in_part.tracks if inside(h)])
    tracker.dropped[:] = [d for d in tracker.dropped if not inside(d)]
    tracker.forget([t])
    return t.centre_m.copy()


def survey_and_pick(
    survey: Callable[[], FruitsResult],
    harvest_round: Callable[[FruitsResult], HarvestResult],
    drop: Callable[[int], None],
    rounds: int,
) -> tuple[FruitsResult, HarvestResult | None]:
    """Survey, harvest, and (``rounds`` > 0) survey and harvest again while a harvest picks.

    Args:
        survey: one survey of the zone from where the arm is (the tracker keeps its tracks).
        harvest_round: the harvest of a survey's localised fruit, its visits saying which
            fruit each picked.
        drop: ``drop(track_id)``: a picked fruit's track leaves the tracker and the planner.
        rounds: how many surveys may follow a harvest that picked.
    Returns:
        the rounds joined (module docstring), and every visit (None when the first survey
        ended with no track).
    """
    if isinstance(rounds, bool) or not isinstance(rounds, int) or rounds < 0:
        raise ValueError(f"rounds must be an integer >= 0, got {rounds!r}")
    result = survey()
    if not result.final:
        return result, None
    views, wall = list(result.views), result.wall_s
    order: list[int] = []
    visits: list[Visit] = []
    basket: list[FruitState] = []  # the picked fruit's states when picked
    for k in range(rounds + 1):
        done = harvest_round(result)
        order += done.order
        visits += [dataclasses.replace(v, round=k) for v in done.visits]
        taken = [v.track for v in done.visits if v.picked is not None]
        if not taken or k == rounds or result.outcome == Outcome.CONVERGED:
            break
        by_id = {f.id: f for f in result.final}
        basket += [by_id[t] for t in taken]
        for t in taken:
            drop(t)
        result = survey()
        first = views[-1].iteration + 1
        views += [
            dataclasses.replace(v, iteration=first + v.iteration, fruits=(*basket, *v.fruits))
            for v in result.views
        ]
        wall += result.wall_s
    joined = FruitsResult(tuple(views), wall, result.outcome, result.shape)
    return joined, HarvestResult(tuple(order), tuple(visits))
