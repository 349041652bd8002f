"""Fruit taken off the plant in a compiled scene, and put back.

A picking arm takes a fruit with its calyx and leaves the pedicel on the truss
(:mod:`bve_mj.loop.picking`). In the compiled scene that is the fruit's flesh geom and its
calyx geom (a mesh of its own: :func:`~bve_mj.sim.scene_model.fruit_calyx_name`) moved
:data:`PICKED_DROP_M` below the scene, out of every view and of every distance the arm's
clearance measures. The compiled scene is shared by the episodes of a process
(:func:`bve_mj.loop.start.start_episode` keeps the last few), so what is taken is put back
when the episode ends (:meth:`Basket.put_back`, called by the world's ``close``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np

from bve_mj.sim.scene_model import SceneInfo, fruit_calyx_name, fruit_geom_name

__all__ = ["PICKED_DROP_M", "Basket"]

PICKED_DROP_M = 20.0
"""How far below the scene a picked fruit's geoms go [m]."""


@dataclass
class Basket:
    """The fruit picked from ``model`` (the scene ``info`` describes), in order."""

    model: mujoco.MjModel
    info: SceneInfo
    _moved: dict[int, np.ndarray] = field(default_factory=dict)  # geom id → its place in the scene
    _names: list[str] = field(default_factory=list)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self._names)

    def take(self, name: str) -> None:
        """Move fruit ``name``'s flesh and calyx out of the scene (a scene written before
        calyces were geoms of their own has only the flesh to move); the caller runs the
        kinematics again (``mj_forward``) before the next image.

        Raises:
            KeyError: when the scene has no fruit ``name``, or it was taken already."""
        if name not in {f.name for f in self.info.fruits}:
            raise KeyError(f"no fruit {name!r} in the scene")
        if name in self._names:
            raise KeyError(f"fruit {name!r} was picked already")
        for geom in (fruit_geom_name(name), fruit_calyx_name(name)):
            gid = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_GEOM, geom)
            if gid >= 0:
                self._moved[gid] = self.model.geom_pos[gid].copy()
                self.model.geom_pos[gid, 2] -= PICKED_DROP_M
        self._names.append(name)

    def put_back(self) -> None:
        """Every fruit taken back where it grew (the compiled scene as it was)."""
        for gid, pos in self._moved.items():
            self.model.geom_pos[gid] = pos
        self._moved.clear()
        self._names.clear()
