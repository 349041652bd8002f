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

The arm keeps clear of what the robot knows, the fruit it tracks and the canopy in which the
rest hang (:mod:`bve_mj.loop.arm_clearance`).

The move to the pre-approach pose (the controller's straight joint-space path, sampled) keeps
every arm geom clear of every known fruit's sphere and in front of the canopy; the approach
and the retreat keep every geom clear of the spheres, and all but the hand (the last joint's
link: the flange and the camera) in front of the canopy. Look-at IK for both poses, then the
position controller drives the arm in physics. Every few physics steps of the moves the least
distance between the arm's geoms and every true fruit's geom is measured (MuJoCo's
``mj_geomDistance``): a visit touches a fruit when it falls to zero.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from bve_mj.config import Settings
from bve_mj.estimation.visibility import visible_arc_deg
from bve_mj.geometry import camera_rotation, unit
from bve_mj.loop.arm_clearance import (
    CANOPY_MARGIN_M,
    PATH_CLEARANCE_M,
    FruitClearance,
    Obstacles,
)
from bve_mj.loop.fruit_records import FruitState
from bve_mj.planning.plan import ViewPlan
from bve_mj.robot.ik import IkOptions, look_at_ik
from bve_mj.sim.arm_boxes import deepest_x
from bve_mj.sim.mujoco_world import MujocoWorld
from bve_mj.sim.scene_model import SceneInfo

__all__ = ["CLEARANCE_M", "RETREAT_M", "HarvestResult", "RecordsHarvest", "Visit", "harvest", "harvest_order"]

CLEARANCE_M = 0.03
"""The camera keeps at least this from every other known fruit's sphere at a visit's pose [m]."""

RETREAT_M = 0.1
"""The pre-approach pose: the camera this much farther from the fruit than the visit pose,
on the same line [m] (a round tomato's diameter and more: the hand enters the canopy only on
the straight approach)."""


_EXPOSURE_CLASS_DEG = 30.0


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
        picked: the fruit the visit took off the plant (``tracking.pick_rounds`` > 0:
            :mod:`bve_mj.loop.picking`), by name; None when it took none or picking is off.
        round: the harvest round it belongs to (0 first; later ones follow a new survey).
    """

    track: int
    order: int
    reached: bool
    distance_m: float
    true_distance_m: float
    clearance_m: float
    reason: str | None = None
    picked: str | None = None
    round: int = 0


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
            "picked": [v.picked for v in self.visits if v.picked is not None],
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
    pick: Callable[[FruitState], str | None] | None = None,
) -> HarvestResult:
    """Order the localised fruit and visit each (module docstring), keeping the arm from every
    confirmed track of ``fruits``, every fruit ``seen_in_part`` and the canopy; ``recorder``
    (a video) is told the order and each visit, and sees every physics step of the moves.
    ``pick(fruit)``: after a visit that reached its pose, take the fruit there off the plant
    (its name, recorded in :attr:`Visit.picked`; None: nothing there to take)."""
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
        visit = _visit(world, by_id[tid], known, settings, info, k, on_step)
        if pick is not None and visit.reached:
            visit = dataclasses.replace(visit, picked=pick(by_id[tid]))
        visits.append(visit)
        if recorder is not None:
            recorder.on_visited(visits[-1])
    return HarvestResult(tuple(order), tuple(visits))


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
            known.clearance(world, world.q, pre.q) < PATH_CLEARANCE_M
            or known.clearance(world, pre.q, ik.q, hand=False) < PATH_CLEARANCE_M
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
    depth = deepest_x(world, world.q) - known.canopy_x_m
    if not depth > 0.0:
        return
    p, R = world.kin.camera_pose(world.q)
    p_back = p - (depth + CANOPY_MARGIN_M) * np.array([1.0, 0.0, 0.0])
    look = p_back + 0.3 * R[:, 0]
    ik = look_at_ik(world.kin, p_back, look, world.q, rng, options)
    if ik.success and known.clearance(world, world.q, ik.q) >= PATH_CLEARANCE_M:
        world.move_camera(ViewPlan(p_back, look, "optimal", True, 0.0, q=ik.q))


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
