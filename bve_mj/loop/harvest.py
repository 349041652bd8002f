"""The harvest: once every fruit is localised, the order to pick them in, and the arm's visit
to each (the camera within ``episode.approach_distance_m`` of the fruit, as the one-target
approach mode ends).

**Order** (documented rule): the most exposed fruit first, then the nearest. Exposure is the
outline a camera at the fruit's approach pose would see of it, the other fruit's discs taken
out (:func:`bve_mj.estimation.visibility.visible_arc_deg`), in 30° classes: a fruit in front
of the truss is cut before one behind it, so the one behind is exposed when its turn comes;
within a class the one nearest the camera goes first (less travel).

**Visit**: approach and retreat along one line, as a picking arm does. The camera goes first
to a pre-approach pose ``RETREAT_M`` farther from the fruit than the visit pose, then
straight in to the visit pose (the approach distance from the estimate, looking at it), then
back out to the pre-approach pose. The line is level, from the fruit towards the arm's
vertical axis (from the aisle: an approach from above, below or the side passes through the
trusses hanging there), or in directions near it (up to 40° away) when a pose on it is
unreachable, when the visit pose comes too close to another known fruit (closer than its
sphere plus ``CLEARANCE_M``), or when the arm would hit something it knows of on the way.

**What the robot knows** (:class:`Obstacles`), never the scene's truth:

- every confirmed track and every fruit seen in part known to within its radius (a sphere:
  estimated centre, radius plus three σmax); tentative tracks, seen once or twice, and
  looser estimates are not obstacles (a false detection's sphere, or one ranged from a
  sliver of outline, would only block visits; the canopy stands for them);
- **the canopy**: trusses hang from the stems on the row's aisle side, so every fruit of the
  row, seen or not (green fruit, other trusses), hangs behind a plane across the row's normal
  (the world's +x: the robot faces the row). Its front is the median front of the known
  fruit, less ``CANOPY_MARGIN_M``. The fruit the detector never measured (green ones, other
  trusses) hang there too, so an arm that stays in front of it touches none of them.

The move to the pre-approach pose (the controller's straight joint-space path, sampled) keeps
every arm geom clear of every known fruit's sphere and in front of the canopy; the approach
and the retreat keep every geom clear of the spheres, and all but the hand (the last joint's
link: the flange and the camera) in front of the canopy. Look-at IK for both poses, then the
position controller drives the arm in physics. Every few physics steps of the moves the least
distance between the arm's geoms and every true fruit's geom is measured (MuJoCo's
``mj_geomDistance``): a visit touches a fruit when it falls to zero.
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

__all__ = [
    "CANOPY_MARGIN_M", "CLEARANCE_M", "RETREAT_M", "FruitClearance", "HarvestResult", "Obstacles",
    "RecordsHarvest", "Visit", "harvest", "harvest_order",
]  # fmt: skip

CLEARANCE_M = 0.03
"""The camera keeps at least this from every other fruit's surface at a visit's pose [m]."""

PATH_CLEARANCE_M = 0.0
"""The arm's geoms keep at least this from every known fruit's sphere and the canopy's front
along a visit's moves [m]."""

RETREAT_M = 0.1
"""The pre-approach pose: the camera this much farther from the fruit than the visit pose,
on the same line [m] (a round tomato's diameter and more: the hand enters the canopy only on
the straight approach)."""

CANOPY_MARGIN_M = 0.03
"""The canopy's front lies this far in front of the known fruit's median front [m] (a round
tomato's radius): the trusses of one row hang at depths a few centimetres apart."""

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
        clearance_m: the least distance between the arm's geoms and any true fruit during the
            moves (to the pre-approach pose, in, and back out; ≤ 0: touched).
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
    seen_in_part: Sequence[FruitState] = (),
) -> HarvestResult:
    """Order the localised fruit and visit each (module docstring), keeping the arm from every
    confirmed track of ``fruits``, every fruit ``seen_in_part`` and the canopy; ``recorder``
    (a video) is told the order and each visit, and sees every physics step of the moves."""
    cam = settings.camera
    localised = [f for f in fruits if f.localised]
    known = Obstacles.of([f for f in fruits if f.confirmed], seen_in_part)
    order = harvest_order(localised, world.p_world_camera, cam.focal_px, cam.width_px, cam.height_px)
    by_id = {f.id: f for f in localised}
    visits = []
    on_step = None if recorder is None else recorder.on_step
    if recorder is not None:
        recorder.on_order(order)
    for k, tid in enumerate(order):
        if recorder is not None:
            recorder.on_visit(tid)
        visits.append(_visit(world, by_id[tid], known, settings, info, k, on_step))
        if recorder is not None:
            recorder.on_visited(visits[-1])
    return HarvestResult(tuple(order), tuple(visits))


@dataclass(frozen=True)
class Obstacles:
    """What the arm keeps clear of on a visit (module docstring).

    Attributes:
        ids: the track (or fruit seen in part, negative: ``-1 - id``) of each sphere.
        spheres: (n, 4): centre [m] and radius plus three σmax [m].
        canopy_x_m: the canopy's front along the row's normal (world x) [m]; inf with no
            fruit known.
    """

    ids: tuple[int, ...]
    spheres: np.ndarray
    canopy_x_m: float

    @classmethod
    def of(cls, tracks: Sequence[FruitState], seen_in_part: Sequence[FruitState] = ()) -> Obstacles:
        """Spheres of the ``tracks`` and of the fruit ``seen_in_part`` known to within their
        radius (3σmax ≤ the estimated radius; a looser one, ranged from a sliver of outline,
        says little where the fruit is and would block every approach near it: the canopy
        stands for it); the canopy's front from the same fruit."""
        kept = [(f, f.id) for f in tracks] + [(f, -1 - f.id) for f in seen_in_part]
        kept = [(f, i) for f, i in kept if 3.0 * f.belief.sigma_max_m <= float(f.belief.mean[3])]
        spheres = np.array(
            [[*f.belief.centre_m, float(f.belief.mean[3]) + 3.0 * f.belief.sigma_max_m] for f, _ in kept]
        ).reshape(-1, 4)
        fronts = [float(f.belief.centre_m[0] - f.belief.mean[3]) for f, _ in kept]
        front = float(np.median(fronts)) - CANOPY_MARGIN_M if fronts else math.inf
        return cls(tuple(i for _, i in kept), spheres, front)

    def without(self, track: int) -> np.ndarray:
        """The spheres of every obstacle but the track ``track`` (the fruit visited), (m, 4)."""
        return self.spheres[[i != track for i in self.ids]].reshape(-1, 4)


def _visit(
    world: MujocoWorld,
    fruit: FruitState,
    known: Obstacles,
    settings: Settings,
    info: SceneInfo,
    order: int,
    on_step: Callable[[float], None] | None = None,
) -> Visit:
    """Visit one fruit (pre-approach pose, in, back out); ``on_step`` (a video's hook) sees
    every physics step of the moves."""
    target = fruit.belief.centre_m
    rng = np.random.default_rng(fruit.id)
    options = IkOptions(restarts=4, upright=settings.planner.upright > 0.0)
    clearance = FruitClearance(world, info)
    hook: Callable[[float], None] = clearance.step
    if on_step is not None:
        recorded = on_step

        def both(sim_time: float) -> None:
            clearance.step(sim_time)
            recorded(sim_time)

        hook = both
    reason: str | None = None
    world.set_step_hook(hook)
    try:
        _leave_canopy(world, known, rng, options)
        poses, reason = _approach(world, fruit, known, settings.episode.approach_distance_m, rng, options)
        if poses is not None:
            (p_pre, q_pre), (p, q) = poses
            world.move_camera(ViewPlan(p_pre, target, "optimal", True, 0.0, q=q_pre))
            world.move_camera(ViewPlan(p, target, "optimal", True, 0.0, q=q))
            clearance.step(0.0, force=True)
            if world.last.move is None or not world.last.move.settled:
                reason = "the arm did not settle at the pose"
        here = world.kin.camera_pose(world.q)[0]
        if poses is not None:
            world.move_camera(ViewPlan(p_pre, target, "optimal", True, 0.0, q=q_pre))  # back out
    finally:
        world.set_step_hook(on_step)
    truths = np.array([f.centre_m for f in info.fruits])
    return Visit(
        fruit.id, order, reason is None, float(np.linalg.norm(here - target)),
        float(np.min(np.linalg.norm(truths - here, axis=1))), clearance.least_m, reason,
    )  # fmt: skip


Pose = tuple[np.ndarray, np.ndarray]  # camera position [m], joint angles [rad]


def _approach(
    world: MujocoWorld,
    fruit: FruitState,
    known: Obstacles,
    distance_m: float,
    rng: np.random.Generator,
    options: IkOptions,
) -> tuple[tuple[Pose, Pose] | None, str | None]:
    """The first approach line (module docstring) whose pre-approach and visit poses are
    reachable and clear: ((pre-approach pose, visit pose), None), or (None, why not)."""
    target = fruit.belief.centre_m
    others = known.without(fruit.id)
    base = _unit(-target * [1.0, 1.0, 0.0])  # level, towards the arm's vertical axis: from the aisle
    blocked = False
    for yaw, el in ((0, 0), (20, 0), (-20, 0), (0, 20), (0, -20), (40, 0), (-40, 0), (0, 40)):
        u = _turn(base, math.radians(yaw), math.radians(el))
        p, p_pre = target + distance_m * u, target + (distance_m + RETREAT_M) * u
        if np.any(np.linalg.norm(others[:, :3] - p, axis=1) < others[:, 3] + CLEARANCE_M):
            continue
        pre = look_at_ik(world.kin, p_pre, target, world.q, rng, options)
        if not pre.success:
            continue
        ik = look_at_ik(world.kin, p, target, pre.q, rng, options)
        if not ik.success:
            continue
        if (
            _path_clearance(world, world.q, pre.q, known.spheres, known.canopy_x_m) < PATH_CLEARANCE_M
            or _path_clearance(world, pre.q, ik.q, known.spheres, known.canopy_x_m, hand=False)
            < PATH_CLEARANCE_M
        ):
            blocked = True
            continue
        return ((p_pre, pre.q), (p, ik.q)), None
    if blocked:
        return None, "every reachable approach passes too close to a known fruit or into the canopy"
    return None, "no reachable pose clear of the other fruit"


def _leave_canopy(world: MujocoWorld, known: Obstacles, rng: np.random.Generator, options: IkOptions) -> None:
    """When the arm is behind the canopy's front (the last view's pose may reach into it),
    draw the camera straight back across the row, looking the way it looks, until the arm's
    farthest geom is ``CANOPY_MARGIN_M`` in front of it; held where it is when that move is
    unreachable or would pass closer to a known fruit."""
    depth = _deepest_x(world, world.q) - known.canopy_x_m
    if not depth > 0.0:
        return
    p, R = world.kin.camera_pose(world.q)
    p_back = p - (depth + CANOPY_MARGIN_M) * np.array([1.0, 0.0, 0.0])
    look = p_back + 0.3 * R[:, 0]
    ik = look_at_ik(world.kin, p_back, look, world.q, rng, options)
    if (
        ik.success
        and _path_clearance(world, world.q, ik.q, known.spheres, known.canopy_x_m) >= PATH_CLEARANCE_M
    ):
        world.move_camera(ViewPlan(p_back, look, "optimal", True, 0.0, q=ik.q))


def _deepest_x(world: MujocoWorld, q: np.ndarray) -> float:
    """The farthest x any of the arm's geoms (its box) reaches at q [m]."""
    m = world.model
    data = mujoco.MjData(m)
    data.qpos[:] = world.data.qpos
    data.qpos[world.qpos_adr] = q
    mujoco.mj_kinematics(m, data)
    return max(_box_max_x(m, data, g) for g in _arm_geoms(m, world.kin.joint_names))


def _box_half(m: mujoco.MjModel, g: int) -> np.ndarray:
    """A geom's half sizes as a box (a cylinder as the box around it)."""
    half = m.geom_size[g]
    if m.geom_type[g] == mujoco.mjtGeom.mjGEOM_CYLINDER:
        return np.array([half[0], half[0], half[1]])
    return np.asarray(half)


def _box_max_x(m: mujoco.MjModel, data: mujoco.MjData, g: int) -> float:
    """The farthest x of a geom's box [m]."""
    return float(data.geom_xpos[g][0] + np.abs(data.geom_xmat[g].reshape(3, 3)[0]) @ _box_half(m, g))


def _path_clearance(
    world: MujocoWorld,
    q_from: np.ndarray,
    q_to: np.ndarray,
    spheres: np.ndarray,
    canopy_x_m: float = math.inf,
    hand: bool = True,
) -> float:
    """The least distance between the arm's geoms and the ``spheres`` (n, 4: centre, radius)
    or the canopy's front over the straight joint-space path ``q_from`` → ``q_to`` (sampled),
    each arm geom taken as its box (a cylinder as the box around it) [m]; negative: inside.

    The canopy's front is the plane x = ``canopy_x_m``; ``hand`` False: the last joint's link
    (flange and camera) may enter it (the approach). A move that starts inside (the last
    view's pose may be) is measured against its way out: a geom inside a sphere or behind
    the canopy's front at ``q_from`` may not go deeper than it starts."""
    if len(spheres) == 0 and not math.isfinite(canopy_x_m):
        return math.inf
    m = world.model
    data = mujoco.MjData(m)
    data.qpos[:] = world.data.qpos
    arm = _arm_geoms(m, world.kin.joint_names)
    in_canopy = set(arm) if hand else set(arm) - set(_arm_geoms(m, world.kin.joint_names[-1:]))
    inside: dict[int, np.ndarray] = {}  # each geom's depth into each sphere at q_from (≤ 0)
    behind: dict[int, float] = {}  # each geom's depth behind the canopy's front at q_from (≥ 0)
    least = math.inf
    for s in np.linspace(0.0, 1.0, _PATH_SAMPLES):
        data.qpos[world.qpos_adr] = q_from + s * (np.asarray(q_to) - q_from)
        mujoco.mj_kinematics(m, data)
        for g in arm:
            if len(spheres):
                half = _box_half(m, g)
                local = (spheres[:, :3] - data.geom_xpos[g]) @ data.geom_xmat[g].reshape(3, 3)  # geom frame
                gap = np.linalg.norm(local - np.clip(local, -half, half), axis=1) - spheres[:, 3]
                least = min(least, float(np.min(gap - inside.setdefault(g, np.minimum(gap, 0.0)))))
            if g in in_canopy and math.isfinite(canopy_x_m):
                gap_x = canopy_x_m - _box_max_x(m, data, g)
                least = min(least, gap_x + behind.setdefault(g, max(-gap_x, 0.0)))
    return least


def _arm_geoms(m: mujoco.MjModel, joint_names: Sequence[str]) -> list[int]:
    """Every geom of the arm's bodies and their descendants."""
    arm_bodies = {m.jnt_bodyid[m.joint(n).id] for n in joint_names}
    return [g for g in range(m.ngeom) if _root_in(m, int(m.geom_bodyid[g]), arm_bodies)]


class FruitClearance:
    """The least distance between the arm's geoms and every true fruit's geom [m] (at most
    0.05 m is measured), measured every few physics steps of a move (call :meth:`step` from
    the world's step hook)."""

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
