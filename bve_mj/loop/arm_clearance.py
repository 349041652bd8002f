"""What the arm keeps clear of, and how close it came: the harvest's visits, the every-fruit
views (the BVE's and, through :class:`BaselineClearance`, the baselines') and the one-target
loop's moves (:class:`ClearMovesPlanner`).

**What the robot knows** (:class:`Obstacles`), never the scene's truth:

- every confirmed track and every fruit seen in part known to within its radius (a sphere:
  estimated centre, radius plus three σmax); tentative tracks, seen once or twice, and
  looser estimates are not obstacles (a false detection's sphere, or one ranged from a
  sliver of outline, would only block moves; the canopy stands for them);
- **the canopy**: trusses hang from the stems on the row's aisle side, so every fruit of the
  row, seen or not (green fruit, other trusses), hangs behind a plane across the row's normal
  (the world's +x: the robot faces the row). Its front is the median front of the known
  fruit, less ``CANOPY_MARGIN_M``. The fruit the detector never measured (green ones, other
  trusses) hang there too, so an arm that stays in front of it touches none of them.

:func:`~bve_mj.sim.arm_boxes.path_clearance` measures a joint-space move (the controller's
straight path, sampled) against them, each arm geom taken as its box. :class:`FruitClearance`
measures, in physics, the least distance between the arm's geoms and every true fruit
(MuJoCo's ``mj_geomDistance``): a move touches a fruit when it falls to zero.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Protocol

import mujoco
import numpy as np

from bve_mj.errors import PlanningError
from bve_mj.estimation.belief import Belief
from bve_mj.planning.constraints import Constraint
from bve_mj.planning.plan import Planner, PlannerAround, ViewPlan
from bve_mj.robot.ik import IkOptions, look_at_ik
from bve_mj.sim.arm_boxes import arm_geoms, path_clearance
from bve_mj.sim.mujoco_world import MujocoWorld
from bve_mj.sim.scene_model import SceneInfo, fruit_geom_name

__all__ = [
    "CANOPY_MARGIN_M",
    "PATH_CLEARANCE_M",
    "BaselineClearance",
    "ClearMovesPlanner",
    "FruitClearance",
    "KnownFruit",
    "Obstacles",
    "retreat_view",
]

PATH_CLEARANCE_M = 0.0
"""The arm's geoms keep at least this from every known fruit's sphere and the canopy's front
along a move [m]."""

CANOPY_MARGIN_M = 0.03
"""The canopy's front lies this far in front of the known fruit's median front [m] (a round
tomato's radius): the trusses of one row hang at depths a few centimetres apart."""

_CHECK_EVERY = 10  # physics steps between clearance checks


class KnownFruit(Protocol):
    """A fruit the robot knows of: a track or a fruit seen in part (its id and belief over
    centre and radius)."""

    @property
    def id(self) -> int: ...

    @property
    def belief(self) -> Belief: ...


@dataclass(frozen=True)
class Obstacles:
    """What the arm keeps clear of (module docstring).

    Attributes:
        ids: the track (or fruit seen in part, negative: ``-1 - id``) of each sphere.
        spheres: (n, 4): centre [m] and radius plus three σmax [m].
        canopy_x_m: the canopy's front along the row's normal (world x) [m]: the median of
            the known fruit's fronts less ``CANOPY_MARGIN_M`` (the median: one track ranged
            wrong, a cherry taken for a nearer larger fruit, does not move it); inf with no
            fruit known.
    """

    ids: tuple[int, ...]
    spheres: np.ndarray
    canopy_x_m: float

    @classmethod
    def of(
        cls, tracks: Sequence[KnownFruit], seen_in_part: Sequence[KnownFruit] = (), radius_m: float = 0.0
    ) -> Obstacles:
        """Spheres of the ``tracks`` and of the fruit ``seen_in_part`` known to within their
        radius (3σmax ≤ the estimated radius; a looser one, ranged from a sliver of outline,
        says little where the fruit is and would block every approach near it: the canopy
        stands for it); the canopy's front from the same fruit. ``radius_m``: the radius of a
        belief without one (the paper's centre-only state)."""
        every = [(f, f.id) for f in tracks] + [(f, -1 - f.id) for f in seen_in_part]
        kept = [
            (f.belief.centre_m, r, f.belief.sigma_max_m, i)
            for f, i in every
            for r in [radius_m if f.belief.radius_m is None else f.belief.radius_m]
            if 3.0 * f.belief.sigma_max_m <= r
        ]
        spheres = np.array([[*c, r + 3.0 * sigma] for c, r, sigma, _ in kept]).reshape(-1, 4)
        fronts = [float(c[0] - r) for c, r, _, _ in kept]
        front = float(np.median(fronts)) - CANOPY_MARGIN_M if fronts else math.inf
        return cls(tuple(i for *_, i in kept), spheres, front)

    def clearance(
        self,
        world: MujocoWorld,
        q_from: np.ndarray,
        q_to: np.ndarray,
        *,
        hand: bool = True,
        leaving: bool = False,
    ) -> float:
        """:func:`path_clearance` of the move ``q_from`` → ``q_to`` against these [m]."""
        return path_clearance(world, q_from, q_to, self.spheres, self.canopy_x_m, hand=hand, leaving=leaving)

    def without(self, track: int) -> np.ndarray:
        """The spheres of every obstacle but the track ``track`` (the fruit visited), (m, 4)."""
        return self.spheres[[i != track for i in self.ids]].reshape(-1, 4)


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
        self.arm = arm_geoms(m, world.kin.joint_names)
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


@dataclass(frozen=True)
class _Target:
    id: int
    belief: Belief


class ClearMovesPlanner(PlannerAround):
    """``planner`` in the one-target loop, whose moves keep the arm clear of the fruit it
    localises (its sphere once it is known to within its radius, :class:`Obstacles`; a fruit
    of ``radius_m`` where the state holds no radius) and of the canopy in front of it (the
    loop tracks no other fruit: its neighbours hang there). Searching, from the band
    distance, the canopy's front is the fruit's once it is known to within its radius (as
    the every-fruit views take it); in ``approach`` mode, where the arm goes in to the fruit,
    it is the fruit's front less three σmax and ``CANOPY_MARGIN_M`` from the first view
    (known or loose), and the hand (flange and camera) may enter it, as a harvest's approach
    does, the rest of the arm not. A plan whose move is not clear raises
    :class:`~bve_mj.errors.PlanningError`, and the loop holds the camera (event
    ``planner_failed``); the planner is told the view it planned failed (where it learns
    from failed views), or it would plan the same blocked move from the same belief again,
    view after view: a camera held where the last view was learns nothing new to change it
    (``plum`` 4148988863: ten views held so, the episode 12 mm off at its end). A plan
    without joint angles is passed on unchecked."""

    def __init__(self, planner: Planner, world: MujocoWorld, radius_m: float, approach: bool = False) -> None:
        super().__init__(planner)
        self.world = world
        self.radius_m = radius_m
        self.approach = approach

    def plan(self, belief: Belief, p_world_camera: np.ndarray, iteration: int) -> ViewPlan:
        plan = self.planner.plan(belief, p_world_camera, iteration)
        if plan.q is None:
            return plan
        known = Obstacles.of([_Target(0, belief)], radius_m=self.radius_m)
        canopy = known.canopy_x_m
        if self.approach:  # the canopy in front of the fruit's front wherever it may be (3σ
            # nearer), even while it is known too loosely to be an obstacle itself
            r = self.radius_m if belief.radius_m is None else belief.radius_m
            canopy = float(belief.centre_m[0]) - r - 3.0 * belief.sigma_max_m - CANOPY_MARGIN_M
        q_now, hand = self.world.q, not self.approach
        clear = path_clearance(self.world, q_now, plan.q, known.spheres, canopy, hand=hand)
        if clear < PATH_CLEARANCE_M:
            self.note_failed_view(plan.p_world_camera, plan.p_world_target)  # plan elsewhere next
            raise PlanningError(
                f"view {iteration}: the move passes {-1e3 * clear:.0f} mm into the fruit or the canopy"
            )
        return plan


_BASELINE_IK = IkOptions(restarts=4)  # a checked candidate's pose, from the arm's pose now


class BaselineClearance:
    """The clearance check of the every-fruit views for the baselines (random, circle, fixed
    views), which plan camera positions and leave the arm's pose to the move.

    :meth:`constraints` gives the baselines one more expensive task constraint (checked on
    candidates that pass every cheap one, after the arm's reachability; see
    :mod:`bve_mj.planning.baselines`): ``clear``, the look-at IK from the arm's pose now and
    :func:`path_clearance` of the move to it against ``known()`` (value ``PATH_CLEARANCE_M``
    less the clearance, ≤ 0 where clear; 1 m where the IK finds no pose). A random candidate
    that fails it is passed over, a circle or fixed-views point backed off towards the
    camera, as for reachability. :meth:`planner` hands each plan the pose its point was
    checked with, so the arm moves there and nowhere else (a point never checked, the camera
    where it is or a plan restoring feasibility, goes as before: the world solves its IK)."""

    def __init__(self, world: MujocoWorld, known: Callable[[], Obstacles], upright: bool) -> None:
        self.world = world
        self.known = known
        self.options = dataclasses.replace(_BASELINE_IK, upright=upright)
        self._rng = np.random.default_rng(0)
        self._poses: dict[tuple[float, ...], np.ndarray] = {}

    def constraints(self, k_hat: np.ndarray) -> list[Constraint]:
        """The ``clear`` constraint of a plan around the estimate ``k_hat`` (the baselines'
        extra task constraints are built once a plan)."""
        self._poses = {}
        return [_ClearMove(self, np.asarray(k_hat, dtype=float).copy())]

    def clearance_at(self, p_world_camera: np.ndarray, k_hat: np.ndarray) -> float:
        """The clearance of the move to the camera at ``p_world_camera`` looking at ``k_hat``
        [m]; -1 m where no pose reaches it. The pose is kept for :meth:`planner`."""
        world = self.world
        ik = look_at_ik(world.kin, p_world_camera, k_hat, world.q, self._rng, self.options)
        if not ik.success:
            return -1.0
        self._poses[tuple(np.asarray(p_world_camera, dtype=float).tolist())] = ik.q
        known = self.known()
        return known.clearance(world, world.q, ik.q)

    def posed(self, plan: ViewPlan) -> ViewPlan:
        """``plan`` with the pose its point was checked with (unchanged where it was not)."""
        q = self._poses.get(tuple(np.asarray(plan.p_world_camera, dtype=float).tolist()))
        return plan if q is None or plan.q is not None else dataclasses.replace(plan, q=q.copy())

    def planner(self, baseline: Planner) -> Planner:
        """``baseline`` (built with :meth:`constraints` among its extra constraints), its plans
        posed (:meth:`posed`)."""
        return _Posed(baseline, self)


@dataclass(frozen=True)
class _ClearMove:
    """clear(c) ≤ 0: the move to the camera at c keeps the arm clear (:class:`BaselineClearance`)."""

    check: BaselineClearance
    k_hat: np.ndarray
    name: str = "clear"
    expensive: bool = True

    def value(self, c: np.ndarray) -> float:
        return PATH_CLEARANCE_M - self.check.clearance_at(c, self.k_hat)

    def gradient(self, c: np.ndarray) -> np.ndarray:
        raise NotImplementedError("the clearance of a move is checked on candidates, never optimised")


class _Posed(PlannerAround):
    def __init__(self, planner: Planner, check: BaselineClearance) -> None:
        super().__init__(planner)
        self.check = check

    def plan(self, belief: Belief, p_world_camera: np.ndarray, iteration: int) -> ViewPlan:
        return self.check.posed(self.planner.plan(belief, p_world_camera, iteration))


def retreat_view(
    world: MujocoWorld,
    known: Obstacles,
    look_at: np.ndarray,
    step_m: float,
    rng: np.random.Generator,
    upright: bool,
) -> ViewPlan | None:
    """The camera drawn ``step_m`` straight back across the row (towards the aisle, world
    -x), with the arm's pose for it: a view for when the planner finds none (a camera held
    where it is sees what it saw). It looks at ``look_at``, or, where that turn's move is not
    clear, the way it looks now (the smallest move back). The move is checked as one leaving
    the spheres the arm is in (:func:`path_clearance` with ``leaving``: a planner boxed in
    by the clearance check is most often an arm inside a known fruit's sphere, which every
    move deepens somewhere). None where the arm cannot take either or neither move is clear
    of what the robot knows (``known``)."""
    p, R = world.kin.camera_pose(world.q)
    p_back = p - step_m * np.array([1.0, 0.0, 0.0])
    options = IkOptions(restarts=4, upright=upright)
    for look in (np.asarray(look_at, dtype=float), p_back + 0.3 * R[:, 0]):
        if float(np.linalg.norm(look - p_back)) < 1e-6:
            continue
        ik = look_at_ik(world.kin, p_back, look, world.q, rng, options)
        if not ik.success:
            continue
        if known.clearance(world, world.q, ik.q, leaving=True) >= PATH_CLEARANCE_M:
            return ViewPlan(p_back, look.copy(), "optimal", True, 0.0, q=ik.q)
    return None
