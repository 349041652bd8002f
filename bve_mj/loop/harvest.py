"""The harvest: once every fruit is localised, the order to pick them in, and the arm's visit
to each (the camera within ``episode.approach_distance_m`` of the fruit, as the one-target
approach mode ends).

**Order** (documented rule): the most exposed fruit first, then the nearest. Exposure is the
outline a camera at the fruit's approach pose would see of it, the other fruit's discs taken
out (:func:`bve_mj.estimation.visibility.visible_arc_deg`), in 30° classes: a fruit in front
of the truss is cut before one behind it, so the one behind is exposed when its turn comes;
within a class the one nearest the camera goes first (less travel).

**Visit**: the camera at the approach distance from the estimate, looking at it, from the
direction fruit → camera now, or from directions near it (up to 40° away) when that pose is
unreachable or too close to another fruit (closer than its radius plus ``CLEARANCE_M``), or
when the arm would pass too close to a fruit on its way: the straight joint-space path the
controller follows (sampled) must keep every arm geom ``PATH_CLEARANCE_M`` from every track's
sphere (its estimated centre and radius plus three σmax; the margin is in the sphere): what
the robot knows, not the scene's truth. Look-at IK, then the position controller drives the
arm there in physics. Every few physics steps of the move the least distance between the
arm's geoms and every true fruit's geom is measured (MuJoCo's ``mj_geomDistance``): a visit
touches a fruit when it falls to zero.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import mujoco
import numpy as np

from bve_mj.config import Settings
from bve_mj.estimation.visibility import visible_arc_deg
from bve_mj.geometry import camera_rotation, unit
from bve_mj.loop.every_fruit import FruitState
from bve_mj.planning.plan import ViewPlan
from bve_mj.robot.ik import IkOptions, look_at_ik
from bve_mj.sim.mujoco_world import MujocoWorld
from bve_mj.sim.scene_model import SceneInfo, fruit_geom_name

__all__ = ["CLEARANCE_M", "HarvestResult", "RecordsHarvest", "Visit", "harvest", "harvest_order"]

CLEARANCE_M = 0.03
"""The camera keeps at least this from every other fruit's surface at a visit's pose [m]."""

PATH_CLEARANCE_M = 0.0
"""The arm's geoms keep at least this from every track's sphere along a visit's path [m]."""

_PATH_SAMPLES = 16  # configurations checked along a visit's joint-space path

_EXPOSURE_CLASS_DEG = 30.0
_CHECK_EVERY = 10  # physics steps between clearance checks


@dataclass(frozen=True)
class Visit:
    """One fruit visited.

    Attributes:
        track: the track visited; order: its place in the harvest order (0 first).
        reached: IK found a pose and the arm settled there.
        distance_m: camera to the estimate at the end of the move.
        true_distance_m: camera to the nearest true fruit centre at the end.
        clearance_m: the least distance between the arm's geoms and any fruit during the move
            (≤ 0: touched).
        reason: why it was not reached (None when it was).
    """

    track: int
    order: int
    reached: bool
    distance_m: float
    true_distance_m: float
    clearance_m: float
    reason: str | None = None


class RecordsHarvest(Protocol):
    """What a video of the harvest (``bve_mj.reporting.fruits_video.FruitsRecorder``) is told:
    every physics step of the moves, the order, each visit before the move and after it."""

    def on_step(self, sim_time: float) -> None: ...

    def on_order(self, order: Sequence[int]) -> None: ...

    def on_visit(self, track: int) -> None: ...

    def on_visited(self, visit: Visit) -> None: ...


@dataclass(frozen=True)
class HarvestResult:
    """The harvest order and every visit."""

    order: tuple[int, ...]
    visits: tuple[Visit, ...]

    def to_json(self) -> dict[str, Any]:
        return {
            "order": list(self.order),
            "rule": "most exposed first (30 deg classes of the outline seen), then nearest",
            "visits": [vars(v).copy() for v in self.visits],
        }


def harvest_order(
    fruits: Sequence[FruitState], p_world_camera: np.ndarray, focal_px: float, width_px: int, height_px: int
) -> list[int]:
    """Track ids in the order to pick: most exposed first, then nearest (module docstring)."""
    if not fruits:
        return []
    centres = np.array([f.belief.centre_m for f in fruits])
    radii = np.array([float(f.belief.mean[3]) for f in fruits])
    exposure = np.zeros(len(fruits))
    for i, c in enumerate(centres):
        d = _unit(np.asarray(p_world_camera) - c)
        p = c + 0.25 * d
        arcs = visible_arc_deg(centres, radii, p, camera_rotation(p, c), focal_px, width_px, height_px)
        exposure[i] = arcs[i]
    distance = np.linalg.norm(centres - np.asarray(p_world_camera), axis=1)
    cls = np.floor(exposure / _EXPOSURE_CLASS_DEG)
    order = sorted(range(len(fruits)), key=lambda i: (-cls[i], distance[i]))
    return [fruits[i].id for i in order]


def harvest(
    world: MujocoWorld,
    fruits: Sequence[FruitState],
    settings: Settings,
    info: SceneInfo,
    recorder: RecordsHarvest | None = None,
) -> HarvestResult:
    """Order the localised fruit and visit each (module docstring); ``recorder`` (a video)
    is told the order and each visit, and sees every physics step of the moves."""
    cam = settings.camera
    localised = [f for f in fruits if f.localised]
    order = harvest_order(localised, world.p_world_camera, cam.focal_px, cam.width_px, cam.height_px)
    by_id = {f.id: f for f in localised}
    visits = []
    on_step = None if recorder is None else recorder.on_step
    if recorder is not None:
        recorder.on_order(order)
    for k, tid in enumerate(order):
        if recorder is not None:
            recorder.on_visit(tid)
        visits.append(_visit(world, by_id[tid], localised, settings, info, k, on_step))
        if recorder is not None:
            recorder.on_visited(visits[-1])
    return HarvestResult(tuple(order), tuple(visits))


def _visit(
    world: MujocoWorld,
    fruit: FruitState,
    fruits: Sequence[FruitState],
    settings: Settings,
    info: SceneInfo,
    order: int,
    on_step: Callable[[float], None] | None = None,
) -> Visit:
    """Visit one fruit; ``on_step`` (a video's hook) sees every physics step of the move."""
    target = fruit.belief.centre_m
    d = settings.episode.approach_distance_m
    others = [f for f in fruits if f.id != fruit.id]
    kin = world.kin
    rng = np.random.default_rng(fruit.id)
    base = _unit(world.p_world_camera - target)
    pose = None
    spheres = _track_spheres(fruits)
    blocked = False
    upright = settings.planner.upright > 0.0
    for yaw, el in ((0, 0), (20, 0), (-20, 0), (0, 20), (0, -20), (40, 0), (-40, 0), (0, 40)):
        p = target + d * _turn(base, math.radians(yaw), math.radians(el))
        if any(np.linalg.norm(p - f.belief.centre_m) < float(f.belief.mean[3]) + CLEARANCE_M for f in others):
            continue
        ik = look_at_ik(kin, p, target, world.q, rng, IkOptions(restarts=4, upright=upright))
        if not ik.success:
            continue
        if _path_clearance(world, world.q, ik.q, spheres) < PATH_CLEARANCE_M:
            blocked = True
            continue
        pose = (p, ik.q)
        break
    truths = np.array([f.centre_m for f in info.fruits])
    if pose is None:
        here = world.p_world_camera
        reason = (
            "every reachable pose's path passes too close to a fruit"
            if blocked
            else "no reachable pose clear of the other fruit"
        )
        return Visit(
            fruit.id, order, False, float(np.linalg.norm(here - target)),
            float(np.min(np.linalg.norm(truths - here, axis=1))), math.inf, reason,
        )  # fmt: skip
    clearance = _Clearance(world, info)
    hook: Callable[[float], None] = clearance.step
    if on_step is not None:
        recorded = on_step

        def both(sim_time: float) -> None:
            clearance.step(sim_time)
            recorded(sim_time)

        hook = both
    world.set_step_hook(hook)
    try:
        world.move_camera(ViewPlan(pose[0], target, "optimal", True, 0.0, q=pose[1]))
    finally:
        world.set_step_hook(on_step)
    here = world.kin.camera_pose(world.q)[0]
    clearance.step(0.0, force=True)
    settled = world.last.move is not None and world.last.move.settled
    return Visit(
        fruit.id, order, bool(settled), float(np.linalg.norm(here - target)),
        float(np.min(np.linalg.norm(truths - here, axis=1))), clearance.least_m,
        None if settled else "the arm did not settle at the pose",
    )  # fmt: skip


def _track_spheres(fruits: Sequence[FruitState]) -> np.ndarray:
    """(n, 4): every track's estimated centre and radius plus three σmax [m]."""
    return np.array(
        [[*f.belief.centre_m, float(f.belief.mean[3]) + 3.0 * f.belief.sigma_max_m] for f in fruits]
    ).reshape(-1, 4)


def _path_clearance(world: MujocoWorld, q_from: np.ndarray, q_to: np.ndarray, spheres: np.ndarray) -> float:
    """The least distance between the arm's geoms and the ``spheres`` (n, 4: centre, radius)
    over the straight joint-space path ``q_from`` → ``q_to`` (sampled), each arm geom taken
    as its box (a cylinder as the box around it) [m]; negative: inside."""
    if len(spheres) == 0:
        return math.inf
    m = world.model
    data = mujoco.MjData(m)
    data.qpos[:] = world.data.qpos
    arm = _arm_geoms(m, world.kin.joint_names)
    least = math.inf
    for s in np.linspace(0.0, 1.0, _PATH_SAMPLES):
        data.qpos[world.qpos_adr] = q_from + s * (np.asarray(q_to) - q_from)
        mujoco.mj_kinematics(m, data)
        for g in arm:
            half = m.geom_size[g]
            if m.geom_type[g] == mujoco.mjtGeom.mjGEOM_CYLINDER:
                half = np.array([half[0], half[0], half[1]])
            R = data.geom_xmat[g].reshape(3, 3)
            local = (spheres[:, :3] - data.geom_xpos[g]) @ R  # centres in the geom's frame
            outside = np.linalg.norm(local - np.clip(local, -half, half), axis=1)
            least = min(least, float(np.min(outside - spheres[:, 3])))
    return least


def _arm_geoms(m: mujoco.MjModel, joint_names: Sequence[str]) -> list[int]:
    """Every geom of the arm's bodies and their descendants."""
    arm_bodies = {m.jnt_bodyid[m.joint(n).id] for n in joint_names}
    return [g for g in range(m.ngeom) if _root_in(m, int(m.geom_bodyid[g]), arm_bodies)]


class _Clearance:
    """The least distance between the arm's geoms and every fruit geom, measured every few
    physics steps of a move."""

    def __init__(self, world: MujocoWorld, info: SceneInfo) -> None:
        m = world.model
        self.world = world
        self.fruit = [
            mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, fruit_geom_name(f.name)) for f in info.fruits
        ]
        self.fruit = [g for g in self.fruit if g >= 0]
        self.arm = _arm_geoms(m, world.kin.joint_names)
        self.least_m = math.inf
        self._n = 0

    def step(self, sim_time: float, force: bool = False) -> None:
        self._n += 1
        if not force and self._n % _CHECK_EVERY:
            return
        m, d = self.world.model, self.world.data
        for a in self.arm:
            for f in self.fruit:
                dist = mujoco.mj_geomDistance(m, d, a, f, 0.05, None)
                self.least_m = min(self.least_m, float(dist))


def _root_in(m: mujoco.MjModel, body: int, arm: set[int]) -> bool:
    """Whether ``body`` is an arm body or a descendant of one."""
    while body > 0:
        if body in arm:
            return True
        body = int(m.body_parentid[body])
    return False


def _turn(v: np.ndarray, yaw: float, el: float) -> np.ndarray:
    """``v`` turned by ``yaw`` about the vertical and raised by ``el``."""
    c, s = math.cos(yaw), math.sin(yaw)
    w = np.array([c * v[0] - s * v[1], s * v[0] + c * v[1], v[2]])
    h = math.hypot(w[0], w[1])
    a = math.atan2(w[2], h) + el
    return _unit(
        np.array([w[0] / max(h, 1e-9) * math.cos(a), w[1] / max(h, 1e-9) * math.cos(a), math.sin(a)])
    )


def _unit(v: np.ndarray) -> np.ndarray:
    return unit(v, (-1.0, 0.0, 0.0))  # no direction: the robot's side of the row
