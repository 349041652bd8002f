"""The episode loop: observe → fuse → plan → move, the same in every world."""

from __future__ import annotations

import dataclasses
import itertools
import math
import time
from collections.abc import Callable, Sequence

import numpy as np

from bve_mj.config import FilterConfig
from bve_mj.errors import BveError, EstimationError
from bve_mj.estimation import Belief, UpdateResult, filter_update, predict
from bve_mj.estimation.prior_bound import PriorBound
from bve_mj.estimation.sensor_share import sensor_information, sensor_share
from bve_mj.estimation.view_correlation import ViewCorrelation, discounted, new_view_share, shared_dof
from bve_mj.geometry import unit
from bve_mj.loop.claims import Claims, shape_of
from bve_mj.loop.events import Event
from bve_mj.loop.outcomes import Outcome
from bve_mj.loop.records import EpisodeResult, ViewRecord
from bve_mj.loop.stops import StopRules, supported
from bve_mj.loop.verdict import another_fruit_fits_the_prior, contested, outside_prior_bound, second_answer
from bve_mj.planning.plan import (
    LearnsFromFailedViews,
    LearnsFromFusedViews,
    Planner,
    PlanStatus,
    SyncsToEncoders,
    ViewPlan,
)
from bve_mj.sim.world import Observation, ReadsEncoders, ReportsViews, World

__all__ = ["EpisodeLoop", "EpisodeResult", "StopRules", "ViewRecord", "run_episode", "supported"]


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
    identity_odds: float = 1.0,
    prior_bound: PriorBound | None = None,
) -> EpisodeResult:
    """Observe from the start pose, then up to ``steps`` times: plan, move, predict, observe,
    update; ``stop`` may end it early. Outcome: the rule that ended it, "max_views", or
    "never_detected" when no view measured the fruit ("ambiguous" when some view saw more
    than one fruit the estimate allows, event ``ambiguous``); "unreliable" instead when the
    final estimate is not supported by the measurements (:func:`supported`), when two
    measurements it gated out agree on another answer, or when one it gated out, with the
    accepted ones that agree with it, makes another answer as well supported that the claim
    all but excludes (:mod:`bve_mj.loop.verdict`); "ambiguous" too when a view found two
    fruit the estimate allowed, and the prior finds the other at least ``identity_odds``
    times as likely to be the target as the fruit localised (default 1: the prior prefers
    the other); and "ambiguous" when the fruit localised lies outside ``prior_bound`` (the
    box the prior's error is declared to stay in, :class:`PriorBound`) by more than its own
    3.29σ: a neighbour, not the target the prior meant.

    While a view's dispute with the belief stands (:meth:`StopRules.standing_dispute`), a
    planner that learns from failed views is told of the disputing view as one: a view from
    its direction shares its error and cannot settle the dispute, so the planner looks from
    elsewhere (seen in ``truss_cluster``, seed 3976831502: the camera held where the disputing
    view was and ended ``stalled`` 4.3 mm off; told, it took three views from elsewhere and
    ended 0.4 mm off). Likewise, when the camera stalls, up to ``stop.stall_escapes`` times
    (:class:`StopRules`), the planner is told the view it holds at is spent and the episode
    goes on (event ``stall_escaped`` on the next view); a planner that cannot learn from
    failed views ends ``stalled`` as before.

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
    loop = EpisodeLoop(
        world, prior, filter_config, planner, on_view, claims, correlation, identity_odds, prior_bound
    )  # fmt: skip
    loop.start()
    outcome: Outcome | None = None
    noted: ViewRecord | None = None
    escapes = stop.stall_escapes if stop is not None else 0
    escaped: list[Event] = []
    for i in range(1, steps + 1):
        plan, events = _plan_or_hold(planner, loop.belief, world.p_world_camera, i)
        loop.step(plan, escaped + events)
        escaped = []
        outcome = stop.outcome(loop.views, loop.leave_one_out) if stop is not None else None
        stalled = outcome == Outcome.STALLED and escapes > 0 and i < steps  # a view left to take
        if stalled and isinstance(planner, LearnsFromFailedViews):
            # the planner's optimum near here repeats this view's errors: told it is spent,
            # the planner looks elsewhere
            planner.note_failed_view(world.p_world_camera, loop.belief.centre_m)
            escapes -= 1
            escaped = [Event("stall_escaped", f"after view {i}")]
            continue
        if outcome is not None:
            break
        disputed = stop.standing_dispute(loop.views) if stop is not None else None
        if disputed is not None and disputed is not noted and isinstance(planner, LearnsFromFailedViews):
            # a view from where the disputing one was shares its error: look elsewhere
            planner.note_failed_view(disputed.p_world_camera, loop.belief.centre_m)
            noted = disputed
    return loop.finish(outcome)


class EpisodeLoop:
    """The episode loop one view at a time, for a caller that chooses the views itself (the
    Gymnasium environment; :func:`run_episode` drives it with a planner).

    :meth:`start` observes from the start pose; each :meth:`step` moves the camera to a plan,
    predicts, observes and updates; :meth:`finish` gives the result with the outcome (see
    :func:`run_episode`). ``planner`` (optional) is told of failed and fused views and of the
    encoders' angles, as in the closed loop.
    """

    def __init__(
        self,
        world: World,
        prior: Belief,
        filter_config: FilterConfig,
        planner: Planner | None = None,
        on_view: Callable[[ViewRecord], None] | None = None,
        claims: Claims | None = None,
        correlation: tuple[ViewCorrelation, ViewCorrelation] | None = None,
        identity_odds: float = 1.0,
        prior_bound: PriorBound | None = None,
    ) -> None:
        if not (math.isfinite(identity_odds) and identity_odds > 0.0):
            raise ValueError(f"identity_odds: got {identity_odds!r}; allowed: a finite number > 0")
        self.world, self.prior, self.planner = world, prior, planner
        self.identity_odds, self.prior_bound = identity_odds, prior_bound
        self.on_view, self.claims, self.correlation = on_view, claims, correlation
        self.filter_config = filter_config
        self._t0 = time.perf_counter()
        self._Q = np.eye(3) * filter_config.process_sigma_m**2
        self._gate = filter_config.gate_probability
        self._update = filter_update(filter_config.kind, filter_config.ekf_iterations)
        self.belief = prior
        """The filter's belief now (the planner plans with it; the views record the claims)."""
        self.views: list[ViewRecord] = []
        self._rejected: list[Observation] = []  # gated-out measurements since the last accepted one
        self._contested: list[Observation] = []  # gated-out measurements since the last belief reset
        self._accepted: list[Observation] = []  # the measurements fused since the last belief reset
        self._innovations: list[tuple[float, float]] = []  # (NIS, shared_dof) of the accepted, since a reset
        self._fused: list[np.ndarray] = []  # unit directions estimate → camera of the accepted, since a reset
        self._fused_at: list[np.ndarray] = []  # and the camera positions they were taken from [m]
        self._reporting = world if isinstance(world, ReportsViews) else None  # asked once, not at each
        self._encoders = world if isinstance(world, ReadsEncoders) else None  # view: ~0.1 ms a check

    def start(self) -> ViewRecord:
        """The view from the start pose (view 0)."""
        self._fuse(0, None, True, 0.0, [])
        return self.views[-1]

    def step(self, plan: ViewPlan, events: list[Event] | None = None) -> ViewRecord:
        """Move to ``plan``, predict, observe, update: the next view."""
        self.world.move_camera(plan)
        self.belief = predict(self.belief, self._Q)
        self._fuse(len(self.views), plan.status, plan.feasible, plan.plan_s, list(events or []))
        return self.views[-1]

    def finish(self, outcome: Outcome | None) -> EpisodeResult:
        """The result, with ``outcome`` (the stop rule that ended it; None: the views ran out)
        checked as :func:`run_episode` describes."""
        views, belief, update, gate = self.views, self.belief, self._update, self._gate
        if not any(v.measured for v in views):  # whatever stopped it: nothing was ever measured
            ambiguous = any(v.has("ambiguous") for v in views)
            outcome = Outcome.AMBIGUOUS if ambiguous else Outcome.NEVER_DETECTED
        elif outcome is None:
            outcome = Outcome.MAX_VIEWS
        if outcome not in (Outcome.NEVER_DETECTED, Outcome.AMBIGUOUS) and (
            not supported(views, self.filter_config.reset_after_rejections)
            or contested(self.prior, belief, self._contested, gate, update)
            or second_answer(
                self.prior, belief, views[-1].belief, self._accepted, self._contested, gate, update
            )
        ):
            outcome = Outcome.UNRELIABLE
        odds = self.identity_odds
        beyond = outside_prior_bound(self.prior_bound, views[-1].belief) if outcome.localised else None
        if beyond is not None:
            views[-1] = dataclasses.replace(views[-1], events=(*views[-1].events, beyond))
            outcome = Outcome.AMBIGUOUS
        if outcome.localised and another_fruit_fits_the_prior(self.prior, belief, views, odds):
            outcome = Outcome.AMBIGUOUS
        wall = time.perf_counter() - self._t0
        return EpisodeResult(self.prior, tuple(views), wall, outcome, shape_of(self.claims))

    def leave_one_out(self) -> list[Belief]:
        """What the episode would claim now with each measurement fused since the last belief
        reset left out in turn (the others fused again from the prior, in their order; the
        claim's innovation and refusal scales as they are): the claims no single view shaped
        (the prior's, where one measurement is all there is). Empty before the first."""
        accepted, claims = self._accepted, self.claims
        out = []
        for k in range(len(accepted)):
            others = accepted[:k] + accepted[k + 1 :]
            belief = self.prior
            for obs in others:
                belief = self._update(belief, obs.z, obs.model, None).belief
            if claims is not None:
                outlines = [o.outline for o in others]
                refused = sum(not v.measured for v in self.views) / len(self.views)  # as the last claim
                sensor = self._sensor_share(belief, others)
                belief = claims.claim(belief, self._innovations, refused, outlines, sensor)
            out.append(belief)
        return out

    def _sensor_share(self, belief: Belief, fused: Sequence[Observation]) -> np.ndarray | None:
        """The declared sensor errors' share of ``belief`` after the prior and ``fused``."""
        measured = [(o.model, o.sensor_cov) for o in fused]
        return sensor_share(belief.cov, sensor_information(self.prior, measured, belief.mean))

    def _fuse(
        self, i: int, status: PlanStatus | None, feasible: bool, plan_s: float, events: list[Event]
    ) -> None:
        world, planner, views = self.world, self.planner, self.views
        correlation, fused, innovations = self.correlation, self._fused, self._innovations
        rejected, contested = self._rejected, self._contested
        belief = self.belief
        looked_at = belief.centre_m
        obs = world.observe(belief)
        measured, accepted, nis = obs is not None, False, float("nan")
        camera = np.asarray(world.p_world_camera, dtype=float).copy()
        direction = unit(camera - belief.centre_m)
        centre_share = radius_share = 1.0  # a fresh view's
        if obs is not None and correlation is not None and fused:
            taken, taken_at = np.array(fused), np.array(self._fused_at)
            centre_share = new_view_share(correlation[0], taken, direction, taken_at, camera)[0]
            radius_share = new_view_share(correlation[1], taken, direction, taken_at, camera)[0]
            obs = dataclasses.replace(obs, model=discounted(obs.model, centre_share, radius_share))
        if obs is not None:
            try:
                result = self._update(belief, obs.z, obs.model, self._gate)
                if result.accepted:
                    rejected.clear()
                    self._accepted.append(obs)
                else:
                    n = self.filter_config.reset_after_rejections
                    rejected.append(obs)
                    del rejected[: -2 * n]  # the last 2n rejected measurements
                    contested.append(obs)
                    del contested[: -2 * n]
                    reopened = _reopen(self.prior, rejected, n, self._gate, self._update)
                    if reopened is not None:  # the belief had locked onto something wrong
                        reset, self._accepted = reopened
                        events.append(Event("belief_reset"))
                        result = dataclasses.replace(result, belief=reset, accepted=True)
                        rejected.clear()
                        contested.clear()
            except EstimationError as exc:
                raise EstimationError(f"view {i}: {exc}; the episode stops here") from None
            belief, accepted, nis = result.belief, result.accepted, result.nis
        self.belief = belief
        info = self._reporting.view_info() if self._reporting is not None else None
        if info is not None:
            events += [Event(str(e)) for e in (*info.get("events", []), *info.get("faults", []))]  # type: ignore[arg-type]
            if info.get("ik_failed") and not any(e.kind == "ik_failure" for e in events):
                events.append(Event("ik_failed"))
        if accepted:
            if obs is not None:
                innovations.append((nis, shared_dof(obs.model, np.size(obs.z), centre_share, radius_share)))
            fused.append(direction)
            self._fused_at.append(camera)
        restarted = any(e.kind == "belief_reset" for e in events)
        if restarted:
            innovations[:] = innovations[-1:]
            fused[:] = fused[-1:]
            self._fused_at[:] = self._fused_at[-1:]
        sensor = None
        if self.claims is None:
            claimed = belief
        else:  # the share of the views so far, this one included, in which nothing was measured
            refused = (sum(not v.measured for v in views) + (not measured)) / (len(views) + 1)
            outlines = [o.outline for o in self._accepted]
            share = self._sensor_share(belief, self._accepted)
            claimed = self.claims.claim(belief, innovations, refused, outlines, share)
            sensor = self.claims.sensor_part(share, innovations)
        views.append(
            ViewRecord(
                i, world.p_world_camera, status, feasible, plan_s, measured, accepted, nis, claimed, info,
                tuple(events), None if claimed is belief else belief, sensor,
            )
        )  # fmt: skip
        if not accepted and isinstance(planner, LearnsFromFailedViews):
            planner.note_failed_view(world.p_world_camera, looked_at)
        if accepted and correlation is not None and isinstance(planner, LearnsFromFusedViews):
            planner.note_fused_view(world.p_world_camera, looked_at, restart=restarted)
        q = self._encoders.q_measured if self._encoders is not None else None
        if q is not None and isinstance(planner, SyncsToEncoders):
            planner.set_configuration(q)
        if self.on_view is not None:
            self.on_view(views[-1])


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
) -> tuple[Belief, list[Observation]] | None:
    """The episode's prior with ``n`` of the ``rejected`` measurements fused (the newest such
    set), if some ``n`` of them, the newest among them, pass the gate one after another,
    starting from the prior: they agree with each other, and each is geometrically
    plausible (consistent with where the prior says the fruit can be, so a blob of several
    fruit, whose apparent size puts it far too close, is never adopted). The old belief was
    then wrong. None when no such set exists (outliers and false detections do not agree
    with each other or with the prior). Returned with the measurements it fused, in order."""
    if len(rejected) < n:
        return None
    plausible = [obs for obs in rejected if update(prior, obs.z, obs.model, gate).accepted]
    if len(plausible) < n or plausible[-1] is not rejected[-1]:
        return None
    newest = rejected[-1]
    for others in itertools.combinations(reversed(plausible[:-1]), n - 1):
        belief = prior
        fused = [*reversed(others), newest]
        for obs in fused:
            result = update(belief, obs.z, obs.model, gate)
            if not result.accepted:
                break
            belief = result.belief
        else:
            return belief, fused
    return None
