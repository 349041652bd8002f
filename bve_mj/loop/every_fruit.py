"""The episode loop for every fruit of a truss: observe all → assign → fuse each → plan for all
→ move, until every fruit is localised.

Each view measures every ripe fruit in the image; the :class:`~bve_mj.estimation.tracks.
Tracker` assigns the detections to the fruit's tracks (or starts tracks), and the
:class:`~bve_mj.planning.every_fruit.EveryFruitPlanner` chooses the next view by the joint
information it gives the fruit not yet localised. A fruit is localised when its claimed
σmax (the filter's, with the claims of :class:`~bve_mj.loop.claims.Claims`: the fruit's own
offset, its innovations, the share of views that should have seen it and did not) is below
``stop_sigma_m`` after at least ``converge_after`` detections. The episode ends
``converged`` when every track is and the views have explored the zone (from directions
``tracking.explore_span_deg`` apart) and framed all of it (:mod:`bve_mj.planning.
zone_coverage`); ``incomplete`` when every track is but a track was dropped on the way (seen
once, never again from the views planned for it: a fruit the detector could not measure
again, or a false detection), a fruit was seen only in part from several views and never
measured (behind its neighbours: :mod:`bve_mj.estimation.unmeasured`), or part of the zone
could not be framed; ``max_views`` when the budget runs out first, and ``never_detected``
when no view measured a fruit.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from bve_mj.errors import BveError, EstimationError
from bve_mj.estimation.assignment import Sighting
from bve_mj.estimation.belief import Belief
from bve_mj.estimation.models import BearingSizeModel
from bve_mj.estimation.tracks import Tracker
from bve_mj.estimation.unmeasured import explained_in_view, settled, too_small, unexplained
from bve_mj.loop.claims import Claims, shape_of
from bve_mj.loop.events import Event
from bve_mj.loop.fruit_records import FruitsResult, FruitState, FruitsView, claimed
from bve_mj.loop.outcomes import Outcome
from bve_mj.planning.every_fruit import (
    EXPLORE,
    FruitTarget,
    LearnsWhereFruitHide,
    PlansForEveryFruit,
    ReportsCandidates,
)
from bve_mj.planning.plan import ViewPlan
from bve_mj.planning.zone_coverage import ZoneCoverage
from bve_mj.sim.world import ReportsUnmeasured, SeesEveryFruit

__all__ = [
    "SurveyRound",
    "claimed",
    "explored_deg",
    "run_every_fruit",
    "seen_in_part_id",
    "seen_in_part_key",
]


@dataclass(frozen=True)
class SurveyRound:
    """A survey among picking rounds (:mod:`bve_mj.loop.picking`): what the rounds before
    leave it, and when it hands over to a harvest.

    Attributes:
        after_picking: a harvest before took fruit off the plant: a zone with no fruit left
            is an answer (``converged``), not a fruit never detected.
        explored: the unit directions zone centre → camera of the views of the surveys
            before; this survey extends the list (the views span the zone over all of them).
        stall_views: > 0 where a harvest and another survey may follow: the survey also ends
            (``incomplete``) once a fruit no harvest has visited yet (``visited``: the track
            ids a harvest before went to) is localised and this many views in a row have
            localised no other while some fruit is left unlocalised: behind its neighbours,
            most likely, where picking the ones in front will show it.
    """

    after_picking: bool = False
    explored: list[np.ndarray] = field(default_factory=list)
    stall_views: int = 0
    visited: frozenset[int] = frozenset()


def explored_deg(directions: list[np.ndarray]) -> float:
    """The largest angle between two of these unit directions [deg] (0 for fewer than two)."""
    if len(directions) < 2:
        return 0.0
    d = np.array(directions)
    return math.degrees(math.acos(float(np.clip(np.min(d @ d.T), -1.0, 1.0))))


def run_every_fruit(
    world: SeesEveryFruit,
    planner: PlansForEveryFruit,
    tracker: Tracker,
    steps: int,
    stop_sigma_m: float,
    converge_after: int,
    claims: Claims | None = None,
    on_view: Callable[[FruitsView], None] | None = None,
    zone: Belief | None = None,
    seen_in_part: Tracker | None = None,
    coverage: ZoneCoverage | None = None,
    retreat: Callable[[np.ndarray], ViewPlan | None] | None = None,
    survey_round: SurveyRound | None = None,
) -> FruitsResult:
    """Observe from the start pose, then up to ``steps`` times: plan for every fruit, move,
    observe, track; stop when every track is localised and the views span
    ``tracking.explore_span_deg`` around the zone (see the module docstring). While every
    track is localised (or none exists) but the views do not span it, the view explores the
    zone (``zone``: a wide belief over it) from a new direction.

    ``seen_in_part``: a tracker for the fruit the world found but could not measure (a world
    that :class:`~bve_mj.sim.world.ReportsUnmeasured`): one confirmed there and explained by
    no track keeps the episode from saying it found every fruit (``incomplete``).

    ``retreat(p_world_target)``: where the planner finds no view, a view drawn back towards
    the aisle looking at ``p_world_target`` (None where there is none), taken instead of
    holding the camera (event ``retreated``): a held camera sees what it saw, and one the
    arm's clearance check has boxed in stays boxed in (``ripe_truss`` 4234827545 held for
    ten views).

    ``coverage``: the work zone's grid. The episode says it found every fruit only once its
    views have framed ``tracking.zone_framed_share`` of it; until then its exploring views
    aim where a view frames most of what is not framed yet (:meth:`~bve_mj.planning.
    zone_coverage.ZoneCoverage.aim_m`), before they look for new directions.

    ``survey_round``: the survey is one of the picking rounds (:class:`SurveyRound`); None: the
    only survey.

    A planner that fails holds the camera where it is (event ``planner_failed``)."""
    t0 = time.perf_counter()
    views: list[FruitsView] = []
    span = tracker.config.explore_span_deg
    survey_round = SurveyRound() if survey_round is None else survey_round
    after_picking, stall_views, visited = (
        survey_round.after_picking, survey_round.stall_views, survey_round.visited,
    )  # fmt: skip
    seen_from = survey_round.explored  # unit directions zone centre → camera of every view

    tried: dict[int, int] = {}  # views planned for each fruit seen in part

    def look(
        i: int,
        plan: ViewPlan | None,
        target: int | None,
        events: list[Event],
        framing: np.ndarray | None = None,
    ) -> None:
        sightings, camera = world.observe_all()
        t1 = time.perf_counter()
        step = tracker.step(sightings, camera, i, target)
        track_s = time.perf_counter() - t1
        unmeasured: tuple[FruitState, ...] = ()
        if seen_in_part is not None and isinstance(world, ReportsUnmeasured):
            measured = {tid for _, tid in (*step.assigned, *step.started)}
            unmeasured = _seen_in_part(seen_in_part, world.unmeasured(), camera, i, tracker, measured, events)
        alive = {t.id for t in tracker.tracks}
        for e in step.events:
            if e.kind in ("deleted", "merged"):
                planner.forget(e.track)
        assigned = {tid for _, tid in step.assigned}
        for _, tid in step.assigned:
            if tid in alive:
                planner.note_fused_view(tid, world.p_world_camera, tracker.track(tid).centre_m)
        if target is not None and plan is not None and target not in assigned:
            planner.note_failed_view(target, world.p_world_camera, plan.p_world_target)
        if isinstance(planner, LearnsWhereFruitHide):  # predicted to show them, it did not
            for tid in sorted((set(step.expected) - assigned) & alive):
                planner.note_hidden(tid, world.p_world_camera, tracker.track(tid).centre_m)
        info = world.view_info()
        here = world.p_world_camera
        seen_from.append(
            (here - tracker.zone_centre_m) / max(float(np.linalg.norm(here - tracker.zone_centre_m)), 1e-9)
        )
        planner.note_explored(here, tracker.zone_centre_m)
        if coverage is not None:
            before = coverage.share
            known = [t for t in tracker.tracks if t.confirmed]
            blockers = (
                np.array([t.centre_m for t in known]).reshape(-1, 3),
                np.array([t.radius_m for t in known]),
            )
            coverage.note(camera.p_world_camera, camera.R_world_camera, blockers)
            if framing is not None and not coverage.share > before:  # the arm cannot frame it
                coverage.give_up(framing)
                events.append(Event("zone_unframed", f"near {np.round(framing, 3).tolist()}"))
        q = world.q_measured
        if q is not None:
            planner.set_configuration(q)
        states = tuple(claimed(t, claims, stop_sigma_m, converge_after) for t in tracker.tracks)
        views.append(
            FruitsView(
                i, world.p_world_camera, target, None if plan is None else plan.status,
                True if plan is None else plan.feasible, 0.0 if plan is None else plan.plan_s,
                track_s, len(sightings), step, states, info, tuple(events), unmeasured,
                math.nan if coverage is None else coverage.share,
            )
        )  # fmt: skip
        if on_view is not None:
            on_view(views[-1])

    look(0, None, None, [])
    outcome: Outcome | None = None

    def pending() -> list[FruitState]:
        """The fruit seen in part still worth a view planned for them."""
        return [h for h in views[-1].unmeasured if tried.get(h.id, 0) < tracker.config.delete_misses]

    def spanned() -> bool:
        return explored_deg(seen_from) >= span

    def stalled() -> bool:  # picking: harvest what is localised before hunting the hidden
        if stall_views <= 0 or len(views) <= stall_views:
            return False
        now = sum(s.localised for s in views[-1].fruits)
        new = any(s.localised and s.id not in visited for s in views[-1].fruits)
        left = not all(s.localised for s in views[-1].fruits) or bool(pending())
        return new and left and now <= sum(s.localised for s in views[-1 - stall_views].fruits)

    def done() -> bool:
        states = views[-1].fruits
        return (
            (bool(states) or after_picking)
            and all(s.localised for s in states)
            and spanned()
            and not pending()
            and framed()
        )

    def framed() -> bool:
        return coverage is None or coverage.share >= tracker.config.zone_framed_share

    for i in range(1, steps + 1):
        if done():
            outcome = Outcome.CONVERGED
            break
        if stalled():
            outcome = Outcome.INCOMPLETE
            break
        states = views[-1].fruits
        targets = [
            FruitTarget(
                s.id, tracker.track(s.id).belief, s.localised, s.belief.sigma_max_m,
                np.array(tracker.track(s.id).directions).reshape(-1, 3),
                np.array(tracker.track(s.id).cameras).reshape(-1, 3),
            )
            for s in states
        ]  # fmt: skip
        events: list[Event] = []
        parts = pending() if all(s.localised for s in states) else []
        if parts:  # every fruit tracked is localised: measure those seen in part
            targets += [
                FruitTarget(seen_in_part_key(h.id), h.belief, False, h.belief.sigma_max_m) for h in parts
            ]
        framing: np.ndarray | None = None  # where a view that looks for the unframed zone aims
        if all(s.localised for s in states) and not parts:  # look for fruit not yet seen
            aim = zone
            if zone is not None and coverage is not None and not framed():
                if coverage.can_aim:
                    framing = coverage.aim_m(world.p_world_camera)
                    aim = Belief(np.r_[framing, zone.mean[3:]], zone.cov)
                elif (states or after_picking) and spanned():
                    outcome = Outcome.INCOMPLETE  # every fruit found is localised; the rest of
                    break  # the zone cannot be framed: no view left that could find one there
            plan, target = _explore(planner, aim, tracker, world, i, events, retreat), EXPLORE
        else:
            t_plan = time.perf_counter()
            try:
                plan, target = planner.plan(targets, world.p_world_camera, i, world.q_measured)
                events += _unhiding(planner, target)
            except (BveError, ArithmeticError, ValueError, np.linalg.LinAlgError) as exc:
                worst = max(targets, key=lambda f: f.sigma_max_m)
                events.append(Event("planner_failed", f"{type(exc).__name__}: {exc}"))
                plan = _fallback(world, worst.belief.centre_m, retreat, events, t_plan)
                target = worst.id
        if target is not None and target <= seen_in_part_key(0):
            h_id = seen_in_part_id(target)
            tried[h_id] = tried.get(h_id, 0) + 1
        world.move_camera(plan)
        look(i, plan, target, events, framing)
    else:
        if done():
            outcome = Outcome.CONVERGED
    if outcome is None:
        seen = after_picking or any(v.detections for v in views)
        outcome = Outcome.MAX_VIEWS if seen else Outcome.NEVER_DETECTED
    elif outcome == Outcome.CONVERGED and (tracker.dropped or views[-1].unmeasured):
        outcome = Outcome.INCOMPLETE
    return FruitsResult(tuple(views), time.perf_counter() - t0, outcome, shape_of(claims))


def _unhiding(planner: PlansForEveryFruit, target: int) -> list[Event]:
    """The event of a view taken to show fruit ``target`` where its BVE view would not."""
    if not isinstance(planner, ReportsCandidates):
        return []
    kinds = {c.kind for c in planner.last_scores if c.planned_for == target}
    return [Event("unhiding", f"fruit {target}")] if "unhide" in kinds else []


def seen_in_part_key(h_id: int) -> int:
    """The planner key (and ``planned_for``) of a view planned for fruit ``h_id`` seen in part:
    below :data:`~bve_mj.planning.every_fruit.EXPLORE`, apart from the track ids (≥ 0)."""
    return EXPLORE - 1 - h_id


def seen_in_part_id(key: int) -> int:
    """The fruit seen in part a planner key is for (inverse of :func:`seen_in_part_key`)."""
    return EXPLORE - 1 - key


def _seen_in_part(
    seen_in_part: Tracker,
    weak: list[Sighting],
    camera: BearingSizeModel,
    iteration: int,
    tracker: Tracker,
    measured: set[int],
    events: list[Event],
) -> tuple[FruitState, ...]:
    """Track this view's fruit seen in part (those whose circle is no fragment's, and that are
    not a tracked fruit partly hidden in this view) and return those confirmed in the zone
    that no track explains. A track ``measured`` in this view (a detection assigned to it, or
    started it) is not also seen in part in it: a circle on its image is a fruit behind it
    (``truss_cluster`` 1745651037: a hidden fruit seen in part on the target's image in four
    views, each taken for the target, which those views measured, and the episode claimed
    every fruit). One that a measured track shows to be its own fruit is forgotten before
    the view's evidence is fused (:func:`~bve_mj.estimation.unmeasured.settled`, event
    ``seen_in_part_settled``). Weak evidence never ends an episode: a belief it breaks (a
    radius driven through zero) restarts it (event ``seen_in_part_reset``)."""
    r0, sd = tracker.radius_prior
    zone_centre, zone_m = tracker.zone_centre_m, tracker.config.zone_m
    r_min = r0 - math.sqrt(3.0) * sd  # the prior's smallest fruit (uniform ±spread)
    hidden_in_part = [t for t in tracker.tracks if t.id not in measured]
    weak = [
        w
        for w in weak
        if not too_small(w, zone_centre, zone_m, r_min) and not explained_in_view(w, hidden_in_part)
    ]
    try:
        gone = settled(seen_in_part.tracks, tracker.tracks)  # before this view's evidence: see settled
        events += [Event("seen_in_part_settled", f"p{h.id} is track {t.id}") for h, t in gone]
        seen_in_part.forget([h for h, _ in gone])
        seen_in_part.step(weak, camera, iteration)
        found = unexplained(seen_in_part.tracks, tracker.tracks, zone_centre, zone_m)
    except (EstimationError, np.linalg.LinAlgError) as exc:
        events.append(Event("seen_in_part_reset", f"{type(exc).__name__}: {exc}"))
        seen_in_part.forget()
        return ()
    return tuple(FruitState(h.id, h.belief, h.confirmed, h.hits, h.misses, h.expected, False) for h in found)


def _explore(
    planner: PlansForEveryFruit,
    zone: Belief | None,
    tracker: Tracker,
    world: SeesEveryFruit,
    iteration: int,
    events: list[Event],
    retreat: Callable[[np.ndarray], ViewPlan | None] | None = None,
) -> ViewPlan:
    """A view exploring the zone, or (no zone belief, or the planner fails) the fallback."""
    t0 = time.perf_counter()
    if zone is not None:
        try:
            return planner.explore(zone, world.p_world_camera, iteration, world.q_measured)
        except (BveError, ArithmeticError, ValueError, np.linalg.LinAlgError) as exc:
            events.append(Event("planner_failed", f"exploring: {type(exc).__name__}: {exc}"))
    return _fallback(world, tracker.zone_centre_m, retreat, events, t0)


def _fallback(
    world: SeesEveryFruit,
    look_at: np.ndarray,
    retreat: Callable[[np.ndarray], ViewPlan | None] | None,
    events: list[Event],
    t0: float,
) -> ViewPlan:
    """Where the planner found no view: the view ``retreat`` draws back, or the camera held."""
    back = None if retreat is None else retreat(look_at)
    if back is not None:
        events.append(Event("retreated"))
        plan = dataclasses.replace(back, status="fallback", feasible=False)
    else:
        plan = ViewPlan(world.p_world_camera, look_at, "fallback", False, math.nan)
    return dataclasses.replace(plan, plan_s=time.perf_counter() - t0)
