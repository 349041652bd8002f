"""The arm as boxes: how far it is from spheres and a plane, posed or moving.

Each of the arm's geoms (every geom of the arm's bodies and their descendants, in the world's
scene) is taken as its box (a cylinder as the box around it). :func:`path_clearance` measures
the straight joint-space path of a move (the controller's, sampled) against spheres (what the
robot knows of the fruit) and a plane x = const (the canopy's front); :func:`deepest_x` how
far into the row a pose reaches. What those spheres and that plane are, and which moves
may enter them, is :mod:`bve_mj.loop.arm_clearance`'s.
"""

from __future__ import annotations

import math
import weakref
from collections.abc import Sequence
from dataclasses import dataclass

import mujoco
import numpy as np

from bve_mj.sim.mujoco_world import MujocoWorld

__all__ = ["arm_geoms", "deepest_x", "path_clearance"]

_PATH_SAMPLES = 16  # configurations checked along a joint-space move


def deepest_x(world: MujocoWorld, q: np.ndarray) -> float:
    """The farthest x any of the arm's geoms (its box) reaches at q [m]."""
    m = world.model
    boxes = _ArmBoxes.of(world)
    data = boxes.scratch
    data.qpos[:] = world.data.qpos
    data.qpos[world.qpos_adr] = q
    mujoco.mj_kinematics(m, data)
    return max(_box_max_x(m, data, g) for g in boxes.geoms.tolist())


@dataclass(frozen=True)
class _ArmBoxes:
    """A world's arm geoms (every geom of the arm's bodies), their box half sizes (k, 3),
    which of them are not the hand's (the last joint's link), and a scratch ``MjData`` the
    measurements pose the arm in (the world's own is its simulation's): made once per world
    (:meth:`of`; a new ``MjData`` was ~1 ms of a 2 ms path check) and gone with it (kept by a
    weak reference to the world: keyed by the model, the ``MjData``'s own reference to its
    model would keep every episode's model alive). Only its ``qpos`` is ever written, each
    time whole, as a new ``MjData``'s would be."""

    geoms: np.ndarray
    half: np.ndarray
    not_hand: np.ndarray
    scratch: mujoco.MjData

    @classmethod
    def of(cls, world: MujocoWorld) -> _ArmBoxes:
        try:
            boxes = _ARM_BOXES.get(world)
        except TypeError:  # a world that cannot be weakly referenced: made each time
            return cls._make(world)
        if boxes is None:
            boxes = _ARM_BOXES[world] = cls._make(world)
        return boxes

    @classmethod
    def _make(cls, world: MujocoWorld) -> _ArmBoxes:
        m, names = world.model, world.kin.joint_names
        geoms = arm_geoms(m, names)
        hand = set(arm_geoms(m, names[-1:]))
        return cls(
            np.array(geoms), np.array([_box_half(m, g) for g in geoms]).reshape(-1, 3),
            np.array([g not in hand for g in geoms]), mujoco.MjData(m),
        )  # fmt: skip


_ARM_BOXES: weakref.WeakKeyDictionary[MujocoWorld, _ArmBoxes] = weakref.WeakKeyDictionary()


def _box_half(m: mujoco.MjModel, g: int) -> np.ndarray:
    """A geom's half sizes as a box (a cylinder as the box around it)."""
    half = m.geom_size[g]
    if m.geom_type[g] == mujoco.mjtGeom.mjGEOM_CYLINDER:
        return np.array([half[0], half[0], half[1]])
    return np.asarray(half)


def _box_max_x(m: mujoco.MjModel, data: mujoco.MjData, g: int) -> float:
    """The farthest x of a geom's box [m]."""
    return float(data.geom_xpos[g][0] + np.abs(data.geom_xmat[g].reshape(3, 3)[0]) @ _box_half(m, g))


def path_clearance(
    world: MujocoWorld,
    q_from: np.ndarray,
    q_to: np.ndarray,
    spheres: np.ndarray,
    canopy_x_m: float = math.inf,
    hand: bool = True,
    leaving: bool = False,
) -> float:
    """The least distance between the arm's geoms and the ``spheres`` (n, 4: centre, radius)
    or the canopy's front over the straight joint-space path ``q_from`` → ``q_to`` (sampled),
    each arm geom taken as its box (a cylinder as the box around it) [m]; negative: inside.

    The canopy's front is the plane x = ``canopy_x_m``; ``hand`` False: the last joint's link
    (flange and camera) may enter it (the approach). A move that starts inside (the last
    view's pose may be) is measured against its way out: a geom inside a sphere or behind
    the canopy's front at ``q_from`` may not go deeper than it starts. ``leaving``: a move
    out of an arm tangled with the spheres (:func:`~bve_mj.loop.arm_clearance.retreat_view`):
    a geom inside a sphere at ``q_from`` is not measured against that sphere at all (it is
    leaving it); every other geom and sphere, and the canopy, as above."""
    if len(spheres) == 0 and not math.isfinite(canopy_x_m):
        return math.inf
    m = world.model
    boxes = _ArmBoxes.of(world)
    data = boxes.scratch
    data.qpos[:] = world.data.qpos
    arm, half = boxes.geoms, boxes.half  # (k,), (k, 3)
    in_canopy = np.ones(len(arm), dtype=bool) if hand else boxes.not_hand
    pos, R = [], []  # every sample's geom positions (S, k, 3) and rotations (S, k, 3, 3)
    for s in np.linspace(0.0, 1.0, _PATH_SAMPLES):
        data.qpos[world.qpos_adr] = q_from + s * (np.asarray(q_to) - q_from)
        mujoco.mj_kinematics(m, data)
        pos.append(data.geom_xpos[arm])
        R.append(data.geom_xmat[arm].reshape(-1, 3, 3))
    P, Rs = np.array(pos), np.array(R)
    least = math.inf
    if len(spheres):
        # the spheres' centres in each geom's frame, (S, k, n, 3); the gap to each box
        local = np.einsum("sknj,skji->skni", spheres[None, None, :, :3] - P[:, :, None, :], Rs)
        outside = local - np.clip(local, -half[None, :, None, :], half[None, :, None, :])
        gap = np.linalg.norm(outside, axis=3) - spheres[None, None, :, 3]
        inside = np.minimum(gap[0], 0.0)  # each geom's depth into each sphere at q_from (≤ 0)
        if leaving:
            inside = np.where(inside < 0.0, -np.inf, 0.0)
        least = float(np.min(gap - inside))
    if math.isfinite(canopy_x_m) and in_canopy.any():
        farthest = P[:, :, 0] + np.einsum("ski,ki->sk", np.abs(Rs[:, :, 0, :]), half)  # each box's x
        gap_x = canopy_x_m - farthest
        behind = np.maximum(-gap_x[0], 0.0)  # each geom's depth behind the front at q_from (≥ 0)
        least = min(least, float(np.min((gap_x + behind)[:, in_canopy])))
    return least


def arm_geoms(m: mujoco.MjModel, joint_names: Sequence[str]) -> list[int]:
    """Every geom of the arm's bodies and their descendants."""
    arm_bodies = {m.jnt_bodyid[m.joint(n).id] for n in joint_names}
    return [g for g in range(m.ngeom) if _root_in(m, int(m.geom_bodyid[g]), arm_bodies)]


def _root_in(m: mujoco.MjModel, body: int, arm: set[int]) -> bool:
    """Whether ``body`` is an arm body or a descendant of one."""
    while body > 0:
        if body in arm:
            return True
        body = int(m.body_parentid[body])
    return False
