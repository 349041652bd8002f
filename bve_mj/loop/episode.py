"""The episode loop: observe → fuse → plan → move, the same in every world."""

from __future__ import annotations

import dataclasses
import itertools
import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from bve_mj.config import FilterConfig
from bve_mj.errors import BveError, EstimationError
from bve_mj.estimation import Belief, UpdateResult, filter_update, predict
from bve_mj.estimation.view_correlation import ViewCorrelation, discounted, new_view_share
from bve_mj.geometry import unit
from bve_mj.loop.claims import Claims
from bve_mj.loop.events import Event, EventKind
from bve_mj.loop.outcomes import Outcome
from bve_mj.planning.plan import (
    LearnsFromFailedViews,
    LearnsFromFusedViews,
    Planner,
    PlanStatus,
    SyncsToEncoders,
    ViewPlan,
)
from bve_mj.sim.world import Observation, ReadsEncoders, ReportsViews, World

__all__ = ["EpisodeResult", "StopRules", "ViewRecord", "run_episode", "supported"]


@dataclass(frozen=True)
class ViewRecord:
    """One view: where the camera was, what the planner said, what the filter made of it.

    ``iteration`` 0 is the view from the start pose (no plan: status None). ``events``: what
    went wrong and how it was handled (:class:`~bve_mj.loop.events.Event`: ``planner_failed``
    with its reason, ``ik_failed``, ``belief_reset``, ``ambiguous``, and injected faults:
    ``dropped``, ``false_detection``, ``outlier``, ``ik_failure``).
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
    world: dict[str, object] | None = None
    events: tuple[Event, ...] = ()

    def has(self, kind: EventKind) -> bool:
        """Whether an event of this kind happened at this view."""
        return any(e.kind == kind for e in self.events)


@dataclass(frozen=True)
class StopRules:
    """When an episode ends before its last view.

    Attributes:
        sigma_m: the largest posterior standard deviation falls below this ("converged"), with
            at least ``min_accepted`` accepted measurements since the last belief reset.
        stable_m: the estimate moves less than this over ``stable_views`` views, each with an
            accepted measurement ("stable"; a gated-out view does not count as agreement).
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
            and _accepted_since_reset(views) >= self.min_accepted
        ):
            return Outcome.CONVERGED
        if self.stable_m is not None and len(views) > n and all(v.accepted for v in views[-n:]):
            moves = [
                np.linalg.norm(views[-i].belief.centre_m - views[-i - 1].belief.centre_m)
                for i in range(1, n + 1)
            ]
            if max(moves) <= self.stable_m:
                return Outcome.STABLE
        return Outcome.STALLED if stalled else None


def _accepted_since_reset(views: Sequence[ViewRecord]) -> int:
    """Accepted measurements since the last belief reset (the reset's own view counts)."""
    start = max((k for k, v in enumerate(views) if v.has("belief_reset")), default=0)
    return sum(v.accepted for v in views[start:])


def _planned_move(view: ViewRecord) -> bool:
    """The planner chose this view and the arm went there: no planner fallback, no IK failure
    (a camera held by a failure has not run out of better views)."""
    return view.plan_status != "fallback" and not (view.has("ik_failed") or view.has("ik_failure"))


@dataclass(frozen=True)
class EpisodeResult:
    """A finished episode: the prior, every view, the final belief, and the wall time [s]."""

    prior: Belief
    views: tuple[ViewRecord, ...]
    wall_s: float
    outcome: Outcome = Outcome.MAX_VIEWS

    @property
    def final(self) -> Belief:
        return self.views[-1].belief if self.views else self.prior

    def event_counts(self) -> dict[str, int]:
        """How often each kind of event happened, over all views."""
        return dict(Counter(e.kind for v in self.views for e in v.events))


def run_episode(
    world: World,
    planner: Planner,
    prior: Belief,
    filter_config: FilterConfig,
    steps: int,
    stop: StopRules | None = None,
    on_view: Callable[[ViewRecord], None] | None = None,
    claims: Claims | None = None,
    correlation: tuple[ViewCorrelation, ViewCorrelation] | None = None,
) -> EpisodeResult:
    """Observe from the start pose, then up to ``steps`` times: plan, move, predict, observe,
    update; ``stop`` may end it early. Outcome: the rule that ended it, "max_views", or
    "never_detected" when no view measured the fruit ("ambiguous" when some view saw more
    than one fruit the estimate allows, event ``ambiguous``); "unreliable" instead when the
    final estimate is not supported by the measurements (:func:`supported`), or when two
    measurements it gated out agree on another answer (:func:`_contested`).

    ``claims``: what the views record (and the stop rules test) beside the filter's own
    belief, which the planner plans with (see :class:`Claims`); None: the filter's belief.

    ``correlation``: how the errors of the centre and of the apparent radius of views from
    nearby directions correlate (:mod:`bve_mj.estimation.view_correlation`): each
    measurement is fused as the share of a fresh view it is worth beside the views fused
    since the last reset (directions seen from the estimate); None: views are independent.

    A planner that fails (raises a :class:`BveError`, a numerical error, or returns a
    non-finite point) does not end the episode: the camera holds where it is, looking at the
    estimate, and the view records ``fallback`` and the reason.

    Raises:
        EstimationError: naming the view, when a measurement would put NaN or infinite
            values into the belief (it never does).
    """
    t0 = time.perf_counter()
    Q = np.eye(3) * filter_config.process_sigma_m**2
    gate = filter_config.gate_probability
    update = filter_update(filter_config.kind, filter_config.ekf_iterations)
    belief = prior
    views: list[ViewRecord] = []

    rejected: list[Observation] = []  # gated-out measurements since the last accepted one
    contested: list[Observation] = []  # gated-out measurements since the last belief reset
    innovations: list[tuple[float, int]] = []  # (NIS, dimension) of the accepted, since a reset
    fused: list[np.ndarray] = []  # unit directions estimate → camera of the accepted, since a reset
    reporting = world if isinstance(world, ReportsViews) else None  # asked once, not at each view:
    encoders = world if isinstance(world, ReadsEncoders) else None  # ~0.1 ms a protocol check

    def fuse(i: int, status: PlanStatus | None, feasible: bool, plan_s: float, events: list[Event]) -> None:
        nonlocal belief
        looked_at = belief.centre_m
        obs = world.observe(belief)
        measured, accepted, nis = obs is not None, False, float("nan")
        direction = unit(world.p_world_camera - belief.centre_m)
        if obs is not None and correlation is not None and fused:
            taken = np.array(fused)
            centre_share = new_view_share(correlation[0], taken, direction)[0]
            radius_share = new_view_share(correlation[1], taken, direction)[0]
            obs = dataclasses.replace(obs, model=discounted(obs.model, centre_share, radius_share))
        if obs is not None:
            try:
                result = update(belief, obs.z, obs.model, gate)
                if result.accepted:
                    rejected.clear()
                else:
                    n = filter_config.reset_after_rejections
                    rejected.append(obs)
                    del rejected[: -2 * n]  # the last 2n rejected measurements
                    contested.append(obs)
                    del contested[: -2 * n]
                    reset = _reopen(prior, rejected, n, gate, update)
                    if reset is not None:  # the belief had locked onto something wrong
                        events.append(Event("belief_reset"))
                        result = dataclasses.replace(result, belief=reset, accepted=True)
                        rejected.clear()
                        contested.clear()
            except EstimationError as exc:
                raise EstimationError(f"view {i}: {exc}; the episode stops here") from None
            belief, accepted, nis = result.belief, result.accepted, result.nis
        info = reporting.view_info() if reporting is not None else None
        if info is not None:
            events += [Event(str(e)) for e in (*info.get("events", []), *info.get("faults", []))]  # type: ignore[arg-type]
            if info.get("ik_failed") and not any(e.kind == "ik_failure" for e in events):
                events.append(Event("ik_failed"))
        if accepted:
            innovations.append((nis, np.size(obs.z) if obs is not None else 0))
            fused.append(direction)
        restarted = any(e.kind == "belief_reset" for e in events)
        if restarted:
            innovations[:] = innovations[-1:]
            fused[:] = fused[-1:]
        if claims is None:
            claimed = belief
        else:  # the share of the views so far, this one included, in which nothing was measured
            refused = (sum(not v.measured for v in views) + (not measured)) / (len(views) + 1)
            claimed = claims.claim(belief, innovations, refused)
        views.append(
            ViewRecord(
                i, world.p_world_camera, status, feasible, plan_s, measured, accepted, nis, claimed, info,
                tuple(events),
            )
        )  # fmt: skip
        if not accepted and isinstance(planner, LearnsFromFailedViews):
            planner.note_failed_view(world.p_world_camera, looked_at)
        if accepted and correlation is not None and isinstance(planner, LearnsFromFusedViews):
            planner.note_fused_view(world.p_world_camera, looked_at, restart=restarted)
        q = encoders.q_measured if encoders is not None else None
        if q is not None and isinstance(planner, SyncsToEncoders):
            planner.set_configuration(q)
        if on_view is not None:
            on_view(views[-1])

    fuse(0, None, True, 0.0, [])
    outcome: Outcome | None = None
    for i in range(1, steps + 1):
        plan, events = _plan_or_hold(planner, belief, world.p_world_camera, i)
        world.move_camera(plan)
        belief = predict(belief, Q)
        fuse(i, plan.status, plan.feasible, plan.plan_s, events)
        outcome = stop.outcome(views) if stop is not None else None
        if outcome is not None:
            break
    if not any(v.measured for v in views):  # whatever stopped it: nothing was ever measured
        ambiguous = any(v.has("ambiguous") for v in views)
        outcome = Outcome.AMBIGUOUS if ambiguous else Outcome.NEVER_DETECTED
    elif outcome is None:
        outcome = Outcome.MAX_VIEWS
    if outcome not in (Outcome.NEVER_DETECTED, Outcome.AMBIGUOUS) and (
        not supported(views, filter_config.reset_after_rejections)
        or _contested(prior, belief, contested, gate, update)
    ):
        outcome = Outcome.UNRELIABLE
    return EpisodeResult(prior, tuple(views), time.perf_counter() - t0, outcome)


def supported(views: Sequence[ViewRecord], window: int) -> bool:
    """Whether the final estimate rests on the measurements: at least two accepted since the
    last belief reset, and at most half of the last ``2 * window`` measurements gated out
    (when most recent measurements disagree with the estimate, the estimate is not what the
    camera sees). An episode that fails this ends ``unreliable`` whatever its stop rule said."""
    if _accepted_since_reset(views) < 2:
        return False
    recent = [v for v in views if v.measured][-2 * window :]
    return 2 * sum(not v.accepted for v in recent) <= len(recent)


def _contested(
    prior: Belief,
    final: Belief,
    rejected: Sequence[Observation],
    gate: float | None,
    update: Callable[..., UpdateResult],
) -> bool:
    """Whether the gated-out measurements hold a second answer: two of them that the final
    belief still rejects but that agree with each other and with the prior (fused one after
    the other from the prior, both pass the gate). The views then saw the fruit in two
    places (the accepted ones may be the wrong pair: a biased silhouette fused early gates
    out the right views that follow), and the final estimate is not what the evidence says."""
    if gate is None:
        return False
    left = [obs for obs in rejected if not update(final, obs.z, obs.model, gate).accepted]
    for a, b in itertools.combinations(left, 2):
        first = update(prior, a.z, a.model, gate)
        if first.accepted and update(first.belief, b.z, b.model, gate).accepted:
            return True
    return False


def _plan_or_hold(
    planner: Planner, belief: Belief, p_world_camera: np.ndarray, iteration: int
) -> tuple[ViewPlan, list[Event]]:
    """The planner's plan, or (when it fails) a fallback that holds the camera in place."""
    t0 = time.perf_counter()
    try:
        plan = planner.plan(belief, p_world_camera, iteration)
        if np.all(np.isfinite(plan.p_world_camera)) and np.all(np.isfinite(plan.p_world_target)):
            return plan, []
        reason = "non-finite viewpoint"
    except (BveError, ArithmeticError, ValueError, np.linalg.LinAlgError) as exc:
        reason = f"{type(exc).__name__}: {exc}"
    hold = ViewPlan(
        np.asarray(p_world_camera, dtype=float).copy(), belief.centre_m.copy(), "fallback", False,
        float("nan"), plan_s=time.perf_counter() - t0,
    )  # fmt: skip
    return hold, [Event("planner_failed", reason)]


def _reopen(
    prior: Belief,
    rejected: list[Observation],
    n: int,
    gate: float | None,
    update: Callable[..., UpdateResult],
) -> Belief | None:
    """The episode's prior with ``n`` of the ``rejected`` measurements fused (the newest such
    set), if some ``n`` of them, the newest among them, pass the gate one after another,
    starting from the prior: they agree with each other, and each is geometrically
    plausible (consistent with where the prior says the fruit can be, so a blob of several
    fruit, whose apparent size puts it far too close, is never adopted). The old belief was
    then wrong. None when no such set exists (outliers and false detections do not agree
    with each other or with the prior)."""
    if len(rejected) < n:
        return None
    plausible = [obs for obs in rejected if update(prior, obs.z, obs.model, gate).accepted]
    if len(plausible) < n or plausible[-1] is not rejected[-1]:
        return None
    newest = rejected[-1]
    for others in itertools.combinations(reversed(plausible[:-1]), n - 1):
        belief = prior
        for obs in (*reversed(others), newest):
            result = update(belief, obs.z, obs.model, gate)
            if not result.accepted:
                break
            belief = result.belief
        else:
            return belief
    return None
