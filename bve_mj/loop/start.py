"""How an episode starts: the seeded scene, the arm's ready pose, the prior.

Seeding: ``SeedSequence(seed)`` spawns the scene, the prior, the sensors, the planner and the
fault streams (in that order), so the same seed gives the same scene, start and noise
whatever the planner, measurement or number of fruit localised.
"""

from __future__ import annotations

import copy
import math
from collections import OrderedDict
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np

from bve_mj.config import CameraConfig, EpisodeConfig, RobotConfig, SceneConfig, Settings
from bve_mj.errors import PlanningError
from bve_mj.estimation.belief import Belief
from bve_mj.estimation.noise import NoiseModel
from bve_mj.estimation.partial_colour import detector_noise_model
from bve_mj.estimation.prior_bound import PriorBound
from bve_mj.geometry import ray_frame
from bve_mj.robot import ArmKinematics, IkOptions, arm_kinematics, look_at_ik
from bve_mj.robot.ik import image_roll_rad, look_at_residuals
from bve_mj.sim.scene import build_scene
from bve_mj.sim.scene_model import Fruit, SceneInfo, fruit_geom_name
from bve_mj.sim.true_boxes import visible_share

__all__ = [
    "KEPT_SCENES",
    "START_MARGIN",
    "EpisodeStart",
    "calibration_sigmas",
    "clear_kept_scenes",
    "detection_prior",
    "detection_prior_bounded",
    "start_episode",
    "state_prior",
]


START_MARGIN = 0.15
"""A ready pose is taken once its joints all keep this share of their range from the limits."""


_ELEVATIONS = (0.15, 0.35, -0.1, 0.6, -0.3)
_YAWS = (0.0, 0.3, -0.3)
_RANDOM_STARTS = 7
_WORTH_SOLVING = 1e-2
"""A start whose screened look-at residual ends above this is not solved again: it failed (a
solved one ends below 1e-5; the tolerances allow about 1e-3)."""


KEPT_SCENES = 2
"""Compiled scenes (and ready poses) a process keeps for the episodes that follow.

The cells of a campaign are paired: run ``i`` of every cell (another planner, measurement,
experiment) draws the same scene from the same seed, and its episodes differ only after it.
A worker that runs them one after another builds, compiles and renders the scene once (a
render context is kept with its model: :mod:`bve_mj.sim.render`): ~0.5 s of a ~0.9 s E5
episode on a 2-core CPU. The compiled model is read-only to an episode (its state lives in
its ``MjData``), so sharing it changes no result (tests/test_scene_reuse.py)."""

START_VISIBLE_SHARE = 5.0 / 9.0
"""A ready pose must show the target this much (of 9 rays to its face, the most): the
detection prior is a first detection of it from there, and a fruit hidden behind its
neighbour would have been the neighbour's (seen in a drawn cocktail cluster: the prior's ray
through the target and the fruit 28 mm in front of it, the episode localised the front one,
30 mm off the target, claiming σmax 2 mm)."""

_SceneKey = tuple[RobotConfig, SceneConfig, CameraConfig, int, bool]
_SCENES: OrderedDict[_SceneKey, tuple[mujoco.MjModel, SceneInfo]] = OrderedDict()
_READY: OrderedDict[tuple[Any, ...], tuple[np.ndarray, Mapping[str, Any]]] = OrderedDict()


def clear_kept_scenes() -> None:
    """Forget the compiled scenes and ready poses this process kept (:data:`KEPT_SCENES`)."""
    _SCENES.clear()
    _READY.clear()


def _keep(cache: OrderedDict[Any, Any], key: Any, value: Any) -> None:
    cache[key] = value
    while len(cache) > KEPT_SCENES:
        cache.popitem(last=False)


def _read_only(info: SceneInfo) -> SceneInfo:
    """``info`` with the arrays of its fruit read-only: shared by the episodes of one scene,
    which read them only (a write raises, rather than changing the next episode's truth)."""
    for fruit in info.fruits:
        for value in vars(fruit).values():
            if isinstance(value, np.ndarray):
                value.flags.writeable = False
    return info


def _compiled_scene(
    s: Settings, kin: ArmKinematics, seed: int, scene_ss: np.random.SeedSequence, leaves: bool
) -> tuple[mujoco.MjModel, SceneInfo]:
    """The seeded scene, compiled; the same model object for the same scene settings and seed
    as one of the last :data:`KEPT_SCENES` episodes of this process."""
    key: _SceneKey = (s.robot, s.scene, s.camera, seed, leaves)
    kept = _SCENES.get(key)
    if kept is None:
        spec, info = build_scene(kin, s.scene, np.random.default_rng(scene_ss), s.camera, leaves=leaves)
        kept = (spec.compile(), _read_only(info))
        _keep(_SCENES, key, kept)
    _SCENES.move_to_end(key)
    return kept


def _ready_pose(
    s: Settings,
    kin: ArmKinematics,
    estimate: np.ndarray,
    rng: np.random.Generator,
    sees: tuple[Any, Callable[[np.ndarray], bool]] | None = None,
) -> np.ndarray:
    """:func:`_start_configuration` for the episode's estimate, remembered with the state it
    leaves ``rng`` in (a pure function of its inputs: the same bits either way); ``sees``:
    a key naming the scene and target, and whether a configuration's camera sees it."""
    upright = s.planner.upright > 0.0
    seen_key = None if sees is None else sees[0]
    key = (s.robot, estimate.tobytes(), s.band_distance_m, upright, repr(rng.bit_generator.state), seen_key)
    kept = _READY.get(key)
    if kept is None:
        q = _start_configuration(
            kin, estimate, s.band_distance_m, rng, upright=upright, sees=None if sees is None else sees[1]
        )
        _keep(_READY, key, (q, rng.bit_generator.state))
    else:
        q, rng.bit_generator.state = kept
    _READY.move_to_end(key)
    return q.copy()


def _sees_fruit(model: mujoco.MjModel, kin: ArmKinematics, fruit: Fruit) -> Callable[[np.ndarray], bool]:
    """Whether the camera of the arm at ``q`` sees ``fruit``: at least
    :data:`START_VISIBLE_SHARE` of the rays to its face reach it first
    (:func:`~bve_mj.sim.true_boxes.visible_share`)."""
    data = mujoco.MjData(model)
    adr = [model.jnt_qposadr[model.joint(name).id] for name in kin.joint_names]
    geom = fruit_geom_name(fruit.name)

    def sees(q: np.ndarray) -> bool:
        data.qpos[adr] = q
        mujoco.mj_kinematics(model, data)
        p = kin.camera_pose(q)[0]
        return visible_share(model, data, p, fruit.centre_m, fruit.radius_m, geom) >= START_VISIBLE_SHARE

    return sees


def _start_configuration(
    kin: ArmKinematics, estimate: np.ndarray, distance: float, rng: np.random.Generator,
    *, upright: bool = False, sees: Callable[[np.ndarray], bool] | None = None,
) -> np.ndarray:  # fmt: skip
    """A ready pose: the camera ``distance`` in front of the estimate (robot side), looking at it.

    Viewing directions are tried in order of preference; for each, look-at IK from home and
    from a few random configurations, keeping the solution farthest from the joint limits.
    The first direction whose best solution keeps every joint ``START_MARGIN`` of its range
    from the limits wins (else the best seen); among such solutions, the one whose image is
    nearest upright with ``upright`` (the planner moves the arm locally and keeps the branch it starts in). A
    pose folded against its limits strands the planner: seed 0's approach once stalled
    0.127 m from the fruit with three joints at their limits. With ``sees``, the winner must
    also see the fruit (``sees(q)``); where no direction's does, the first that keeps the
    margin wins as without it (where none keeps it, the best that sees the fruit).

    Most starts fail, and a failing start runs every iteration: all of them are first
    solved at once (:func:`~bve_mj.robot.ik.look_at_residuals`), and only those that come
    near a solution are solved again, one by one, to the bit as before. ``rng`` draws the
    same random starts, and is left in the same state, as a search that draws them
    direction by direction.
    """
    cameras = []
    for elevation in _ELEVATIONS:
        for yaw in _YAWS:
            d = np.array([-math.cos(yaw), math.sin(yaw), elevation])
            cameras.append(estimate + distance * d / np.linalg.norm(d))
    draws = copy.deepcopy(rng)
    starts = [(kin.home, *(kin.random_configuration(draws) for _ in range(_RANDOM_STARTS))) for _ in cameras]
    n = _RANDOM_STARTS + 1
    p_all = np.repeat(np.array(cameras), n, axis=0)
    towards = estimate - p_all
    single = IkOptions(restarts=0, upright=upright)
    residual = look_at_residuals(
        kin, np.array([q for qs in starts for q in qs]), p_all,
        towards / np.linalg.norm(towards, axis=1, keepdims=True), single,
    )  # fmt: skip
    worth = (residual <= _WORTH_SOLVING).reshape(len(cameras), n)
    found: list[tuple[tuple[float, float], np.ndarray]] = []  # each direction's best solution
    unseen: list[np.ndarray] = []  # those that keep the margin but do not see the fruit
    for p, seeds, solve in zip(cameras, starts, worth, strict=True):
        for _ in range(_RANDOM_STARTS):  # the draws a direction's search makes
            kin.random_configuration(rng)
        here: tuple[tuple[float, float], np.ndarray] | None = None
        for seed in (q for q, ok in zip(seeds, solve, strict=True) if ok):
            ik = look_at_ik(kin, p, estimate, seed, rng, single)
            if ik.success:
                margin = kin.limit_margin(ik.q)
                if upright:
                    roll = image_roll_rad(kin.camera_pose(ik.q)[1]) or 0.0
                    key = (min(margin, START_MARGIN), -abs(roll))
                else:
                    key = (margin, 0.0)
                if here is None or key > here[0]:
                    here = (key, ik.q)
        if here is None:
            continue
        found.append(here)
        if here[0][0] >= START_MARGIN:
            if sees is None or sees(here[1]):
                return here[1]
            unseen.append(here[1])
    if unseen:
        return unseen[0]
    if not found:
        raise PlanningError(f"no reachable ready pose looks at the estimate {estimate.round(3).tolist()}")
    seeing = found if sees is None else [h for h in found if sees(h[1])] or found
    return max(seeing, key=lambda h: h[0])[1]  # the first of the best: ties go to the preferred


def detection_prior(
    p_world_camera: np.ndarray,
    truth: np.ndarray,
    ep: EpisodeConfig,
    rng: np.random.Generator,
    fruit_radius_m: float,
) -> Belief:
    """The prior a first detection of the target from ``p_world_camera`` gives: on the ray to
    the fruit, its range off by U[-e, e] (e = ``initial_error_m``; apparent size is a coarse
    range cue) and its bearing by U[-l, l] in each direction across the ray
    (l = :meth:`EpisodeConfig.lateral_error_m` of the assumed ``fruit_radius_m``); covariance
    with those uniforms' σ along and across the ray (at least 1 mm). It says which fruit is
    meant, where a cube around the fruit, in a truss, does not."""
    return detection_prior_bounded(p_world_camera, truth, ep, rng, fruit_radius_m)[0]


def detection_prior_bounded(
    p_world_camera: np.ndarray,
    truth: np.ndarray,
    ep: EpisodeConfig,
    rng: np.random.Generator,
    fruit_radius_m: float,
) -> tuple[Belief, PriorBound]:
    """:func:`detection_prior` and the bound it was drawn within: the box ±e along the ray,
    ±l across it, about the prior's mean (the target lies in it)."""
    ray = truth - p_world_camera
    rho = float(np.linalg.norm(ray))
    U = ray_frame(ray / rho)
    e, lat = ep.initial_error_m, ep.lateral_error_m(fruit_radius_m)
    half = np.array([e, lat, lat])
    offset = rng.uniform(-1.0, 1.0, 3) * half
    sigmas = np.maximum(half / math.sqrt(3.0), 1e-3)
    mean = truth + U @ offset
    return Belief(mean, U @ np.diag(sigmas**2) @ U.T), PriorBound(mean, U, half)


def state_prior(centre: Belief, settings: Settings) -> Belief:
    """The prior over the whole state when the radius is in it: the centre's, the radius of
    the fruit type (``fruit.radius_m``, uniform ± ``radius_spread_rel``: σ = spread·r/√3) and,
    when the sensor declares a calibration error, the camera's biases (principal point as a
    bearing offset σ = ``principal_point_error_px``/f, focal σ = ``focal_error_rel``; a
    small floor keeps the covariance definite when one of them is 0)."""
    fruit = settings.fruit
    sigma_r = max(fruit.radius_m * fruit.radius_spread_rel / math.sqrt(3.0), 1e-5)
    return centre.extended(fruit.radius_m, sigma_r, calibration_sigmas(settings))


def calibration_sigmas(settings: Settings) -> tuple[float, float, float] | None:
    """σ of the camera's calibration biases the state carries (principal point as a bearing
    offset ``principal_point_error_px``/f each way, focal ``focal_error_rel``; a small floor
    keeps the covariance definite when one of them is 0), or None when it carries none
    (:attr:`~bve_mj.config.Settings.estimates_calibration`)."""
    if not settings.estimates_calibration:
        return None
    sensor = settings.sensor
    pp = max(sensor.principal_point_error_px / settings.camera.focal_px, 1e-6)
    return (pp, pp, max(sensor.focal_error_rel, 1e-6))


@dataclass(frozen=True)
class EpisodeStart:
    """Everything an episode starts from.

    Attributes:
        settings: resolved for the MuJoCo world (approach mode applied).
        kin: the arm's kinematics; model: the compiled scene; info: its ground truth.
        q_start: the ready pose, or None when no pose looks at the fruit (unreachable).
        cube: the coarse guess as an isotropic belief (the prior of an unreachable episode).
        prior: the episode's prior (over the centre, and the radius when it is in the state).
        noise: the detector's calibrated noise (with the radius in the state), else None.
        sensor_ss, planner_ss, fault_ss: the seed streams of the sensors, planner, faults.
        prior_bound: the box the prior's error was drawn within (the target lies in it);
            None where there is no prior (unreachable).
    """

    settings: Settings
    kin: ArmKinematics
    model: mujoco.MjModel
    info: SceneInfo
    q_start: np.ndarray | None
    cube: Belief
    prior: Belief
    noise: NoiseModel | None
    sensor_ss: np.random.SeedSequence
    planner_ss: np.random.SeedSequence
    fault_ss: np.random.SeedSequence
    prior_bound: PriorBound | None = None


def start_episode(
    s: Settings,
    seed: int,
    target: Fruit | None = None,
    distractors: tuple[Fruit, ...] | None = None,
    leaves: bool = True,
    edit: Callable[[mujoco.MjSpec], None] | None = None,
) -> EpisodeStart:
    """The seeded scene, the ready pose and the prior of an episode with the resolved settings
    ``s`` (``target``/``distractors``/``leaves``/``edit``: see
    :func:`bve_mj.loop.mujoco.run_mujoco_episode`). A bad noise model file fails here,
    before any work. With the detection prior (one target), the ready pose sees the target
    where one the search reaches does (:data:`START_VISIBLE_SHARE`)."""
    ep = s.episode
    noise = None
    if s.filter.state == "centre_radius":
        noise = detector_noise_model(s)  # a class short of red: its views' own bias and noise
    scene_ss, prior_ss, sensor_ss, planner_ss, fault_ss = np.random.SeedSequence(seed).spawn(5)
    kin = arm_kinematics(s.robot.name, s.robot.limit_set)
    kept = target is None and distractors is None and edit is None
    if kept:
        model, info = _compiled_scene(s, kin, seed, scene_ss, leaves)
    else:  # a scripted scene: built for this episode alone
        spec, info = build_scene(
            kin, s.scene, np.random.default_rng(scene_ss), s.camera,
            target=target, distractors=distractors, leaves=leaves,
        )  # fmt: skip
        if edit is not None:
            edit(spec)
        model = spec.compile()
    prior_rng = np.random.default_rng(prior_ss)
    truth = info.target.centre_m
    coarse = truth + prior_rng.uniform(-ep.initial_error_m, ep.initial_error_m, 3)
    cube = Belief.isotropic(coarse, max(ep.initial_error_m / math.sqrt(3.0), 1e-3))
    streams = (sensor_ss, planner_ss, fault_ss)
    sees = None
    if ep.prior == "detection" and s.tracking.fruits == "target":
        sees = ((s.scene, seed, leaves) if kept else object(), _sees_fruit(model, kin, info.target))
    try:
        q_start = _ready_pose(s, kin, coarse, prior_rng, sees)
    except PlanningError:  # the fruit is out of the arm's reach: a clear outcome, not a crash
        return EpisodeStart(s, kin, model, info, None, cube, cube, noise, *streams)
    if ep.prior == "cube":
        prior, bound = cube, PriorBound.cube(coarse, ep.initial_error_m)
    else:
        p_camera = kin.camera_pose(q_start)[0]
        prior, bound = detection_prior_bounded(p_camera, truth, ep, prior_rng, s.fruit.radius_m)
    if s.filter.state == "centre_radius":
        prior = state_prior(prior, s)
    return EpisodeStart(s, kin, model, info, q_start, cube, prior, noise, *streams, prior_bound=bound)
