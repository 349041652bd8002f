"""One closed-loop episode in the rendered greenhouse: the product's main job.

Seeding: ``SeedSequence(seed)`` spawns the scene, the prior, the sensors and the planner
streams (:mod:`bve_mj.loop.start`), so the same seed gives the same episode whatever the
planner or measurement.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import mujoco
import numpy as np

from bve_mj.config import Settings, settings_to_dict, with_overrides
from bve_mj.config.experiments import EXPERIMENTS
from bve_mj.estimation.belief import Belief
from bve_mj.estimation.claim_shape import GAUSSIAN, ClaimShape
from bve_mj.estimation.noise import INNOVATION_PRIOR_DOF
from bve_mj.estimation.view_correlation import ViewCorrelation
from bve_mj.loop.arm_clearance import ClearMovesPlanner
from bve_mj.loop.claims import Claims, shape_of
from bve_mj.loop.episode import EpisodeResult, StopRules, ViewRecord, run_episode
from bve_mj.loop.faults import FaultyPlanner, FaultyWorld
from bve_mj.loop.outcomes import Outcome
from bve_mj.loop.start import EpisodeStart, detection_prior, start_episode, state_prior
from bve_mj.perception.protocol import Detector
from bve_mj.planning.constraints import ConstraintName
from bve_mj.planning.plan import Planner
from bve_mj.robot import make_arm_planner
from bve_mj.sim.mujoco_world import MujocoWorld
from bve_mj.sim.scene_model import Fruit, SceneInfo
from bve_mj.sim.world import World

__all__ = [
    "EpisodeParts",
    "MujocoEpisode",
    "Recorder",
    "detection_prior",
    "episode_constraints",
    "episode_parts",
    "episode_settings",
    "run_mujoco_episode",
    "state_prior",
]


class Recorder(Protocol):
    """What an episode recorder (``bve_mj.reporting.video.EpisodeRecorder``) offers the episode."""

    def attach(self, world: MujocoWorld, prior: Belief, shape: ClaimShape = GAUSSIAN) -> None:
        """Called once before the first view: ``shape`` the claim's (each view's belief is its
        bound; ``shape.claim`` of it is what the view claims)."""

    def on_step(self, sim_time: float) -> None: ...

    def on_view(self, record: ViewRecord) -> None: ...


def episode_settings(settings: Settings) -> Settings:
    """``settings`` resolved for the MuJoCo world, with approach mode's adaptations.

    :meth:`Settings.for_world` gives the closed loop's defaults where a setting is unset
    (:mod:`bve_mj.config.presets`: the camera measurement, the radius in the state, the NIS
    gate, the distance band and step limit adapted to the arm, Σc at the band distance).
    Approach mode turns the eq. 13 term on (a = 1, b = 4 unless set), drops the band (the
    episode leaves it out of the constraints) and moves the plant wall to
    ``episode.approach_wall_distance_m`` in front of the fruit.
    """
    settings = settings.for_world("mujoco")
    ep = settings.episode
    if not ep.approach:
        return settings
    planner: dict[str, object] = {}
    if settings.planner.approach_aggressiveness == 0.0:
        planner = {"approach_aggressiveness": 1.0, "approach_set_point": 4.0}
    return with_overrides(
        settings, constraints={"wall_distance_m": ep.approach_wall_distance_m}, planner=planner
    )


@dataclass(frozen=True)
class MujocoEpisode:
    """A finished MuJoCo episode with its ground truth."""

    result: EpisodeResult
    info: SceneInfo
    settings: Settings
    seed: int
    q_start: np.ndarray

    @property
    def truth(self) -> np.ndarray:
        return self.info.target.centre_m

    @property
    def final_error_mm(self) -> float:
        return 1e3 * float(np.linalg.norm(self.result.final.centre_m - self.truth))

    @property
    def true_radius_m(self) -> float:
        """The target's equatorial radius [m] (what a radius in the state estimates)."""
        return self.info.target.radius_m

    def standing_dispute(self) -> ViewRecord | None:
        """The view whose measurement disputed the estimate and that no independent view
        settled by the end (:meth:`~bve_mj.loop.stops.StopRules.standing_dispute`), or None."""
        rules = StopRules.for_episode(self.settings.episode, self.settings.measurement.kind)
        return rules.standing_dispute(self.result.views)

    def cramer_rao_mm(self) -> float:
        """√tr of the centre block of the Cramér-Rao bound of the views this episode fused
        (:func:`bve_mj.estimation.metrics.cramer_rao_bound`: the prior, and each accepted view's model
        with the noise it was fused with, at the true state; calibration biases at 0) [mm];
        NaN when nothing was fused."""
        from bve_mj.estimation.metrics import cramer_rao_bound
        from bve_mj.estimation.models import (
            BearingSizeModel,
            CameraModel,
            MeasurementModel,
            RangeModel,
            SizeModel,
        )

        prior = self.result.prior
        camera = self.settings.measurement.kind in ("camera", "auto")
        models: list[MeasurementModel] = []
        for v in self.result.views:
            info: dict[str, Any] = dict(v.world or {})
            det: dict[str, Any] = info.get("detection", {})
            if not v.accepted or "camera_position_m" not in info or "p_camera_m" not in det:
                continue
            p, R = np.asarray(info["camera_position_m"]), np.asarray(info["camera_rotation"])
            if prior.has_radius and "measurement" in info:
                cov = np.asarray(info["measurement"]["cov"])
                models.append(BearingSizeModel(p, R, cov) if camera else SizeModel(p, float(cov[2, 2])))
            elif not prior.has_radius:
                cov = np.asarray(det["cov_camera_m2"])
                b = np.asarray(det["bearing_camera"])
                models.append(CameraModel(p, R, cov) if camera else RangeModel(p, float(b @ cov @ b)))
        if not models:
            return float("nan")
        x_true = np.zeros(prior.dim)
        x_true[:3] = self.truth
        if prior.has_radius:
            x_true[3] = self.true_radius_m
        bound = cramer_rao_bound(prior.cov, models, x_true)
        return 1e3 * float(np.sqrt(np.trace(bound[:3, :3])))

    def to_json(self) -> dict[str, Any]:
        """The ``--json`` document: settings, seed, views, final error, outcome, wall time."""
        views = []
        for v in self.result.views:
            claim = self.result.claim(v)
            views.append(
                {
                    "view": v.iteration,
                    "plan_status": v.plan_status,
                    "plan_feasible": v.plan_feasible,
                    "plan_s": v.plan_s,
                    "measured": v.measured,
                    "accepted": v.accepted,
                    "nis": None if math.isnan(v.nis) else v.nis,
                    "estimate_m": claim.centre_m.tolist(),
                    "covariance_m2": claim.cov[:3, :3].tolist(),
                    "error_mm": 1e3 * float(np.linalg.norm(claim.centre_m - self.truth)),
                    "truth_m": self.truth.tolist(),
                    **self._radius_json(claim),
                    **(v.world or {}),
                    # the loop's events (the world's among them) over the world's own list
                    "events": [str(e) for e in v.events],
                }
            )
        final = self.result.final_claim
        return {
            "settings": settings_to_dict(self.settings),
            "seed": self.seed,
            "scene": {
                "target": {"centre_m": self.truth.tolist(), "radius_m": self.info.target.radius_m},
                "distractors": [
                    {"centre_m": f.centre_m.tolist(), "radius_m": f.radius_m, "colour": f.colour}
                    for f in self.info.distractors
                ],
            },
            "views": views,
            "final_error_mm": self.final_error_mm,
            "final_nees": final.mahalanobis_sq(self.truth),
            "claim_shape": self.result.shape.to_json(),
            "final_filter_nees": self.result.final_filter.mahalanobis_sq(self.truth),
            **self._final_radius_json(final),
            "state": self._state_json(final),
            "outcome": self.result.outcome,
            "disputed_view": None if (disputed := self.standing_dispute()) is None else disputed.iteration,
            "wall_s": self.result.wall_s,
        }

    def _radius_json(self, belief: Belief) -> dict[str, float | None]:
        """The radius estimate, its σ and error [mm] (None without the radius in the state)."""
        r, sd = belief.radius_m, belief.radius_sigma_m
        if r is None or sd is None:
            return {"radius_mm": None, "radius_sigma_mm": None, "radius_error_mm": None}
        return {
            "radius_mm": 1e3 * r,
            "radius_sigma_mm": 1e3 * sd,
            "radius_error_mm": 1e3 * (r - self.true_radius_m),
        }

    def _final_radius_json(self, belief: Belief) -> dict[str, float | None]:
        r = self._radius_json(belief)
        err, sd = r["radius_error_mm"], r["radius_sigma_mm"]
        return {
            "final_radius_mm": r["radius_mm"],
            "final_radius_sigma_mm": sd,
            "radius_error_mm": err,
            "radius_nees": None if err is None or sd is None else (err / sd) ** 2,
        }

    def _state_json(self, belief: Belief) -> dict[str, Any]:
        """The whole final state: its layout, mean and covariance (SI units)."""
        names = ["x_m", "y_m", "z_m", "radius_m", "bias_y_rad", "bias_z_rad", "focal_error_rel"]
        return {"names": names[: belief.dim], "mean": belief.mean.tolist(), "covariance": belief.cov.tolist()}


def episode_constraints(s: Settings) -> tuple[ConstraintName, ...]:
    """The constraints an episode plans under: its experiment's, with the distance band added
    (the arm's reach), or in approach mode removed (the camera comes close)."""
    names: tuple[ConstraintName, ...] = tuple(EXPERIMENTS[s.episode.experiment.upper()].constraints)
    if not s.episode.approach and "band" not in names:
        names = (*names, "band")
    if s.episode.approach:
        names = tuple(n for n in names if n != "band")
    return names


def run_mujoco_episode(
    settings: Settings,
    seed: int,
    *,
    target: Fruit | None = None,
    distractors: tuple[Fruit, ...] | None = None,
    leaves: bool = True,
    recorder: Recorder | None = None,
    edit: Callable[[mujoco.MjSpec], None] | None = None,
    detector: Detector | None = None,
) -> MujocoEpisode:
    """Build the seeded scene, start the arm at a ready pose, run the loop, return the log.

    ``target``/``distractors``/``leaves`` override the scene's draw (scripted scenarios).
    ``recorder`` records a video of the episode (closed by the caller); ``edit(spec)`` may
    add to the scene before it is compiled (an occluding leaf, say). ``detector`` measures
    the fruit in each image instead of the one ``detector.kind`` names (your own, behind the
    :class:`~bve_mj.perception.protocol.Detector` protocol: a box or mask adapter, say).

    It computes with one BLAS thread (:mod:`bve_mj.threads`), as the command line and every
    campaign worker do: the same settings and seed give the same episode in a Python
    session as in ``bve-mj episode`` (a multi-threaded BLAS rounds differently, and a loop
    near an unobservable direction turns that into millimetres).
    """
    from bve_mj.threads import one_blas_thread

    with one_blas_thread():
        return _run(settings, seed, target, distractors, leaves, recorder, edit, detector)


def _run(
    settings: Settings,
    seed: int,
    target: Fruit | None,
    distractors: tuple[Fruit, ...] | None,
    leaves: bool,
    recorder: Recorder | None,
    edit: Callable[[mujoco.MjSpec], None] | None,
    detector: Detector | None = None,
) -> MujocoEpisode:
    start = start_episode(episode_settings(settings), seed, target, distractors, leaves, edit)
    s, kin, info, prior = start.settings, start.kin, start.info, start.prior
    q_start = start.q_start
    if q_start is None:  # the fruit is out of the arm's reach: a clear outcome, not a crash
        return MujocoEpisode(
            EpisodeResult(start.cube, (), 0.0, Outcome.UNREACHABLE), info, s, seed, kin.home.copy()
        )
    parts = episode_parts(start, q_start, recorder, detector=detector)
    try:
        on_view = None if recorder is None else recorder.on_view
        result = run_episode(
            parts.loop_world, parts.planner, prior, s.filter, s.episode.views, parts.stop, on_view,
            parts.claims, parts.correlation, prior_bound=start.prior_bound,
        )  # fmt: skip
    finally:
        parts.world.close()
    return MujocoEpisode(result, info, s, seed, q_start)


@dataclass
class EpisodeParts:
    """What a MuJoCo episode runs with, built from its start: the world (and, with faults
    injected, the faulty world the loop sees), the planner with the arm's kinematics, the
    stop rules, the claims and the view correlation of the calibrated noise."""

    world: MujocoWorld
    loop_world: World
    planner: Planner
    stop: StopRules
    claims: Claims | None
    correlation: tuple[ViewCorrelation, ViewCorrelation] | None


def episode_parts(
    start: EpisodeStart,
    q_start: np.ndarray,
    recorder: Recorder | None = None,
    keep_images: bool = False,
    *,
    detector: Detector | None = None,
) -> EpisodeParts:
    """The world, planner, stop rules, claims and correlation of the episode ``start`` begins
    (the arm at ``q_start``); ``recorder`` is attached to the world; ``keep_images``: the
    world keeps the last eye-in-hand image (a recorder implies it); ``detector``: the world's
    detector (None: the one ``detector.kind`` names)."""
    s, kin, prior = start.settings, start.kin, start.prior
    ep = s.episode
    world = MujocoWorld(
        s, kin, start.model, start.info, q_start, prior.centre_m, np.random.default_rng(start.sensor_ss),
        keep_images=keep_images or recorder is not None,
        on_step=None if recorder is None else recorder.on_step,
        noise=start.noise, detector=detector,
    )  # fmt: skip
    names = episode_constraints(s)
    experiment = EXPERIMENTS[ep.experiment.upper()]
    planner: Planner = ClearMovesPlanner(
        make_arm_planner(s, experiment.loss, names, kin, q_start, np.random.default_rng(start.planner_ss)),
        world,
        s.fruit.radius_m,
        ep.approach,
    )
    loop_world: World = world
    if s.faults.any:
        fault_rng = np.random.default_rng(start.fault_ss)
        loop_world = FaultyWorld(world, s.faults, fault_rng)
        planner = FaultyPlanner(planner, s.faults.planner_failure_p, fault_rng)
    stop = StopRules.for_episode(ep, s.measurement.kind)
    claims, correlation = None, None
    if world.noise is not None:
        claims = Claims.of_detector(
            world.noise, s.fruit.radius_m, INNOVATION_PRIOR_DOF, s.fruit.shape_index,
            size_only=s.measurement.kind not in ("camera", "auto"), partial_colour=s.detector.partial_colour,
        )  # fmt: skip
        correlation = (world.noise.centre_correlation, world.noise.radius_correlation)
    if recorder is not None:
        recorder.attach(world, prior, shape_of(claims))
    return EpisodeParts(world, loop_world, planner, stop, claims, correlation)
