"""Every ripe fruit of the truss, in the rendered greenhouse: ``bve-mj episode --fruits all``.

The episode starts as the one-target episode does (:mod:`bve_mj.loop.start`: the same scene,
ready pose and prior for the same seed); the prior's mean is the centre of the work zone
(``tracking.zone_m``): every ripe fruit measured there gets a track. Then the loop of
:mod:`bve_mj.loop.every_fruit` runs until every track is localised, and (``--approach``) the
arm visits each fruit in the harvest order (:mod:`bve_mj.loop.harvest`).

Ground truth, for the report: the true ripe fruit (ripeness at least the detector's ripe
class, red unless ``detector.ripe_class`` says otherwise) within the zone. Confirmed tracks
are matched to the scene's fruit (any ripeness) by an optimal assignment on distance, within
a fruit's radius; a confirmed track matched to no fruit is a false track.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any, Protocol

import numpy as np

from bve_mj.config import Settings, settings_to_dict, with_overrides
from bve_mj.config.experiments import EXPERIMENTS
from bve_mj.estimation import Belief, filter_update
from bve_mj.estimation.models import BearingSizeModel
from bve_mj.estimation.tracks import Tracker
from bve_mj.estimation.unmeasured import in_zone, tracking_config
from bve_mj.estimation.view_correlation import ViewShares
from bve_mj.estimation.visibility import outline_shown_deg, visible_arc_deg
from bve_mj.loop.arm_clearance import (
    PATH_CLEARANCE_M,
    BaselineClearance,
    Obstacles,
    retreat_view,
)
from bve_mj.loop.claims import Claims
from bve_mj.loop.every_fruit import SurveyRound, run_every_fruit
from bve_mj.loop.fruit_records import FruitMatch, FruitsResult, FruitState, FruitsView
from bve_mj.loop.harvest import HarvestResult, RecordsHarvest, harvest
from bve_mj.loop.mujoco import INNOVATION_PRIOR_DOF, episode_constraints, episode_settings
from bve_mj.loop.outcomes import Outcome
from bve_mj.loop.picking import LOOK_AGAIN_RADII, picked_fruit, survey_and_pick, take_off
from bve_mj.loop.start import calibration_sigmas, start_episode
from bve_mj.loop.unhiding import ArmUnhider
from bve_mj.planning.every_fruit import (
    EveryFruitPlanner,
    FruitTarget,
    PlansForEveryFruit,
    information_gain,
)
from bve_mj.planning.fruit_baselines import PatternPlanner
from bve_mj.planning.plan import ViewPlan
from bve_mj.planning.zone_coverage import ZoneCoverage
from bve_mj.robot import make_arm_planner
from bve_mj.sim.mujoco_world import MujocoWorld
from bve_mj.sim.scene_model import RIPENESS, Fruit, SceneInfo

__all__ = ["FruitMatch", "FruitsEpisode", "RecordsFruits", "ripe_fruit_in_zone", "run_every_fruit_episode"]


class RecordsFruits(RecordsHarvest, Protocol):
    """What a video of an every-fruit episode (``bve_mj.reporting.fruits_video.FruitsRecorder``)
    offers the episode: wired to the world with the true ripe fruit of the work zone, then
    told every view (and, in approach mode, the harvest: :class:`RecordsHarvest`)."""

    def attach(self, world: MujocoWorld, ripe: Sequence[Fruit], zone_centre_m: np.ndarray) -> None: ...

    def on_view(self, view: FruitsView) -> None: ...


def ripe_fruit_in_zone(info: SceneInfo, settings: Settings, zone_centre_m: np.ndarray) -> list[Fruit]:
    """The fruit the episode should localise: ripe (at least the detector's ripe class) and
    within ``tracking.zone_m`` of the zone's centre."""
    least = RIPENESS.index(settings.detector.ripe_class or "red")
    out = []
    for f in info.fruits:
        colour = "turning" if f.colour == "orange" else f.colour
        ripe = colour in RIPENESS and RIPENESS.index(colour) >= least
        if ripe and np.linalg.norm(f.centre_m - zone_centre_m) <= settings.tracking.zone_m:
            out.append(f)
    return out


@dataclass(frozen=True)
class FruitsEpisode:
    """A finished every-fruit episode with its ground truth."""

    result: FruitsResult
    info: SceneInfo
    settings: Settings
    seed: int
    zone_centre_m: np.ndarray
    harvest: HarvestResult | None = None

    @property
    def ripe(self) -> list[Fruit]:
        return ripe_fruit_in_zone(self.info, self.settings, self.zone_centre_m)

    def matches(
        self, states: tuple[FruitState, ...] | None = None
    ) -> tuple[list[FruitMatch], list[FruitState], list[FruitState]]:
        """(a match per true ripe fruit, confirmed tracks on other fruit (less ripe or outside
        the zone), confirmed tracks on no fruit: false tracks), for the tracks ``states`` (by
        default the episode's final ones)."""
        from scipy.optimize import linear_sum_assignment

        tracks = [t for t in (self.result.final if states is None else states) if t.confirmed]
        fruits = list(self.info.fruits)
        ripe = {f.name for f in self.ripe}
        if not tracks:
            return [FruitMatch(f, None, self.result.shape) for f in self.ripe], [], []
        d = np.array([[np.linalg.norm(t.belief.centre_m - f.centre_m) for f in fruits] for t in tracks])
        limit = np.array([f.radius_m for f in fruits])[None, :]
        rows, cols = linear_sum_assignment(np.where(d <= limit, d, 1e3))
        by_fruit: dict[str, FruitState] = {}
        matched: set[int] = set()
        for i, j in zip(rows, cols, strict=True):
            if d[i, j] <= limit[0, j]:
                by_fruit[fruits[j].name] = tracks[i]
                matched.add(int(i))
        other = [
            tracks[i] for i, j in zip(rows, cols, strict=True) if i in matched and fruits[j].name not in ripe
        ]
        false = [t for i, t in enumerate(tracks) if i not in matched]
        return [FruitMatch(f, by_fruit.get(f.name), self.result.shape) for f in self.ripe], other, false

    def views_to_localise(self, within_mm: float) -> int | None:
        """How many views it took until every true ripe fruit of the zone had a localised
        track within ``within_mm`` of it (None: never in this episode, or no ripe fruit)."""
        n, ripe = len(self.result.views), len(self.ripe)
        return next((k for k in range(1, n + 1) if ripe and self.localised_after(k, within_mm) == ripe), None)

    def localised_after(self, views: int, within_mm: float) -> int:
        """How many true ripe fruit of the zone had a localised track within ``within_mm`` of
        them after the first ``views`` views (the start's counted; the episode's end where it
        took fewer)."""
        if views < 1:
            raise ValueError(f"views must be at least 1, got {views}")
        done = self.result.views
        matches, _, _ = self.matches(done[min(views, len(done)) - 1].fruits) if done else ([], [], [])
        return sum(m.localised_within(within_mm) for m in matches)

    def to_json(self) -> dict[str, Any]:
        """The ``--json`` document of ``--fruits all``: settings, seed, per view the tracks and
        what the tracker did, and ``fruits``: per true ripe fruit its truth, radius and the
        matched track's estimate, radius, error, NEES and whether it is localised;
        ``unmatched_tracks`` (false positives), ``other_tracks`` (on fruit less ripe or
        outside the zone), ``seen_in_part`` (fruit seen only in part from several views,
        never measured, explained by no track: where the episode knows it missed one) and
        ``zone_framed`` (the share of the work zone some view framed; None without the check)."""
        matches, other, false = self.matches()
        views = []
        for v in self.result.views:
            views.append(
                {
                    "view": v.iteration,
                    "camera_position_m": v.p_world_camera.tolist(),
                    "planned_for": v.planned_for,
                    "plan_status": v.plan_status,
                    "plan_s": v.plan_s,
                    "track_s": v.track_s,
                    "assign_s": v.tracking.assign_s,
                    "detections": v.detections,
                    "assigned": [list(p) for p in v.tracking.assigned],
                    "started": [list(p) for p in v.tracking.started],
                    "ignored": list(v.tracking.ignored),
                    "expected": list(v.tracking.expected),
                    "events": [f"{e.kind}:{e.track}" for e in v.tracking.events] + [str(e) for e in v.events],
                    "tracks": [t.to_json() for t in v.fruits],
                    "timings_s": (v.world or {}).get("timings_s"),
                    "zone_framed": None if math.isnan(v.zone_framed) else v.zone_framed,
                }
            )
        fruits = []
        for m in matches:
            t = m.track
            fruits.append(
                {
                    "name": m.fruit.name,
                    "truth_m": m.fruit.centre_m.tolist(),
                    "radius_mm": 1e3 * m.fruit.radius_m,
                    "colour": m.fruit.colour,
                    "track": None if t is None else t.id,
                    "estimate_m": None if t is None else t.belief.centre_m.tolist(),
                    "radius_estimate_mm": None if t is None else 1e3 * float(t.belief.mean[3]),
                    "radius_sigma_mm": None if m.claim is None else 1e3 * float(math.sqrt(m.claim.cov[3, 3])),
                    "error_mm": None if t is None else m.error_mm,
                    "nees": None if t is None else m.nees,
                    "localised": bool(t is not None and t.localised),
                }
            )
        return {
            "settings": settings_to_dict(self.settings),
            "seed": self.seed,
            "zone_centre_m": self.zone_centre_m.tolist(),
            "views": views,
            "fruits": fruits,
            "unmatched_tracks": [t.to_json() for t in false],
            "other_tracks": [t.to_json() for t in other],
            "seen_in_part": [t.to_json() for t in self.result.unmeasured],
            "zone_framed": views[-1]["zone_framed"] if views else None,
            "harvest": None if self.harvest is None else self.harvest.to_json(),
            "claim_shape": self.result.shape.to_json(),
            "outcome": self.result.outcome,
            "wall_s": self.result.wall_s,
        }


def run_every_fruit_episode(
    settings: Settings, seed: int, recorder: RecordsFruits | None = None
) -> FruitsEpisode:
    """Build the seeded scene, start the arm at the one-target episode's ready pose, localise
    every ripe fruit of the work zone, and (approach mode) visit each.

    ``recorder`` records a video of the episode (closed by the caller); the episode is the
    same with it as without.

    Raises:
        ConfigError: when the settings cannot localise every fruit (the camera measurement
            with the radius in the state is needed), or pick without approach mode.
    """
    from bve_mj.errors import ConfigError
    from bve_mj.threads import one_blas_thread

    s = episode_settings(settings)
    if s.measurement.kind != "camera" or s.filter.state != "centre_radius":
        raise ConfigError(
            "tracking.fruits", "all", "with measurement.kind = camera and filter.state = centre_radius"
        )
    if s.tracking.pick_rounds and not s.episode.approach:  # the harvest picks: approach mode
        raise ConfigError("tracking.pick_rounds", s.tracking.pick_rounds, "0 unless episode.approach is true")
    # the search runs as a one-target episode without approach mode (with the distance band);
    # approach mode visits the fruit afterwards
    search = episode_settings(with_overrides(settings, episode={"approach": False}))
    with one_blas_thread():
        return _run(s, search, seed, recorder)


def _run(s: Settings, search: Settings, seed: int, recorder: RecordsFruits | None = None) -> FruitsEpisode:
    start = start_episode(search, seed)
    kin, info, noise = start.kin, start.info, start.noise
    zone = start.prior.centre_m.copy()
    if start.q_start is None or noise is None:
        return FruitsEpisode(FruitsResult((), 0.0, Outcome.UNREACHABLE), info, s, seed, zone)
    ep, cam = s.episode, s.camera
    world = MujocoWorld(
        search, kin, start.model, info, start.q_start, zone, np.random.default_rng(start.sensor_ss),
        keep_images=recorder is not None, on_step=None if recorder is None else recorder.on_step, noise=noise,
    )  # fmt: skip
    if recorder is not None:
        recorder.attach(world, ripe_fruit_in_zone(info, s, zone), zone)
    f = cam.focal_px
    min_arc = s.detector.min_arc_deg
    corr = (noise.centre_correlation, noise.radius_correlation)
    shares = ViewShares(*corr)

    rims = s.detector.interior_edge > 0.0

    def shown(i: int, centres: np.ndarray, radii: np.ndarray, positions: np.ndarray) -> np.ndarray:
        return outline_shown_deg(i, centres, radii, positions, f, cam.width_px, cam.height_px, rims=rims)

    def visible_from(centres: np.ndarray, radii: np.ndarray, p: np.ndarray, R: np.ndarray) -> np.ndarray:
        return visible_arc_deg(centres, radii, p, R, f, cam.width_px, cam.height_px, rims=rims) >= min_arc

    def visible(centres: np.ndarray, radii: np.ndarray, model: BearingSizeModel) -> np.ndarray:
        # the tracker counts a miss only where any overlap leaves the outline (a rim is often
        # refused: in truss_cluster most views of a fruit with 150 deg unhidden miss it)
        p, R = model.p_world_camera, model.R_world_camera
        return visible_arc_deg(centres, radii, p, R, f, cam.width_px, cam.height_px) >= min_arc

    def gain(fruit: FruitTarget, p: np.ndarray, R: np.ndarray) -> float:
        x = fruit.belief.mean
        rho = float(np.linalg.norm(x[:3] - p))
        if rho <= x[3]:
            return 0.0
        radius_px = f * math.tan(math.asin(x[3] / rho))
        sc, sr = noise.expected_sigmas_px(radius_px, s.fruit.shape_index)
        cov = np.diag([(sc / f) ** 2, (sc / f) ** 2, (sr / f) ** 2])
        if len(fruit.directions):
            e = (p - x[:3]) / rho
            share_c, share_r = shares(fruit.directions, e, fruit.cameras, p)
            g = np.sqrt([1.0 / share_c, 1.0 / share_c, 1.0 / share_r])
            cov = cov * np.outer(g, g)
        model = BearingSizeModel(p, R, cov)
        return information_gain(fruit.belief, model.jacobian(x), cov)

    names = episode_constraints(search)
    loss = EXPERIMENTS[ep.experiment.upper()].loss
    planner_rng = np.random.default_rng(start.planner_ss)
    q0 = start.q_start

    def make() -> Any:
        q = world.q_measured if world.q_measured is not None else q0
        return make_arm_planner(search, loss, names, kin, q, planner_rng, economical=True)

    fruit = s.fruit
    radius_prior = (fruit.radius_m, max(fruit.radius_m * fruit.radius_spread_rel / math.sqrt(3.0), 1e-5))
    sd = s.tracking.zone_m / 2.0
    zone_belief = Belief(np.r_[zone, radius_prior[0]], np.diag([sd**2] * 3 + [radius_prior[1] ** 2]))
    update = filter_update(s.filter.kind, s.filter.ekf_iterations)
    tracker = Tracker(
        s.tracking, zone, radius_prior, update, visible, corr, calibration_sigmas(s), noise.outliers
    )
    seen_in_part = Tracker(tracking_config(s.tracking), zone, radius_prior, update, visible)

    def known() -> Obstacles:  # the fruit known now (those seen in part: in the work zone)
        near = in_zone(seen_in_part.tracks, zone, s.tracking.zone_m)
        return Obstacles.of([t for t in tracker.tracks if t.confirmed], [h for h in near if h.confirmed])

    def clear(plan: ViewPlan) -> bool:  # the move keeps the arm off the fruit known now
        if plan.q is None:
            return True
        return known().clearance(world, world.q, plan.q) >= PATH_CLEARANCE_M

    def retreat(look_at: np.ndarray) -> ViewPlan | None:  # one step back towards the aisle
        return retreat_view(world, known(), look_at, search.step_m, planner_rng, s.planner.upright > 0.0)

    planner: PlansForEveryFruit
    if s.planner.kind == "bve":
        upright = s.planner.upright > 0.0
        unhide = (
            ArmUnhider(search, names, kin, shown, min_arc, planner_rng, upright, q0)
            if s.tracking.unhide
            else None
        )
        planner = EveryFruitPlanner(make, gain, visible_from, s.tracking.candidates, clear, unhide)
    else:  # a baseline: one pattern for the whole zone, under the same clearance check
        check = BaselineClearance(world, known, s.planner.upright > 0.0)
        q = world.q_measured if world.q_measured is not None else q0
        baseline = make_arm_planner(search, loss, names, kin, q, planner_rng, check.constraints)
        planner = PatternPlanner(check.planner(baseline), zone_belief)
    claims = Claims.of_detector(
        noise, fruit.radius_m, INNOVATION_PRIOR_DOF, fruit.shape_index,
        partial_colour=s.detector.partial_colour,
    )  # fmt: skip
    rounds = s.tracking.pick_rounds
    behind = min_arc if s.tracking.zone_behind_fruit else 0.0
    grid = (zone, s.tracking.zone_m, fruit.radius_m, f, cam.width_px, cam.height_px, s.tracking.max_range_m)

    picked_at: list[np.ndarray] = []  # the fruit picked since the last survey
    views_before = 0  # the views of the surveys before (a video numbers them on)
    surveys = 0
    visited: set[int] = set()  # the tracks a harvest went to
    explored: list[np.ndarray] = []  # every survey's view directions: the span is over all
    coverage = (
        ZoneCoverage(*grid, search.band_distance_m, behind) if s.tracking.zone_framed_share > 0.0 else None
    )

    def survey() -> FruitsResult:  # from where the arm is; after a harvest, framing again around what it took
        nonlocal views_before, surveys
        if coverage is not None and picked_at:
            coverage.look_again_near(np.array(picked_at), LOOK_AGAIN_RADII * fruit.radius_m)
        picked_at.clear()
        first = views_before
        stall = ep.converge_after + 1 if surveys < rounds else 0  # another survey may follow
        surveys += 1

        def on_view(v: FruitsView) -> None:  # the video numbers the views on
            if recorder is not None:
                recorder.on_view(replace(v, iteration=first + v.iteration))

        result = run_every_fruit(
            world, planner, tracker, ep.views, ep.stop_sigma_m, ep.converge_after, claims,
            on_view=None if recorder is None else on_view, zone=zone_belief,
            seen_in_part=seen_in_part, coverage=coverage, retreat=retreat,
            survey_round=SurveyRound(bool(world.picked), explored, stall, frozenset(visited)),
        )  # fmt: skip
        views_before += len(result.views)
        return result

    def pick(state: FruitState) -> str | None:  # the gripper takes the fruit at the estimate
        name = picked_fruit(state.belief.centre_m, info, world.picked)
        if name is not None:
            world.pick(name)
        return name

    def drop(track_id: int) -> None:  # a picked fruit is in the basket: look again around it
        picked_at.append(take_off(tracker, seen_in_part, track_id))
        planner.forget(track_id)

    def harvest_round(r: FruitsResult) -> HarvestResult:
        done = harvest(world, r.final, s, info, recorder, r.unmeasured, pick if rounds else None)
        visited.update(v.track for v in done.visits)
        return done

    try:
        if not s.episode.approach:
            result, visits = survey(), None
        else:
            result, visits = survey_and_pick(survey, harvest_round, drop, rounds)
    finally:
        world.close()
    return FruitsEpisode(result, info, s, seed, zone, visits)
