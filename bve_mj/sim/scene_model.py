"""What a scene is made of: the fruit record, what the scene reports (:class:`SceneInfo`), the
ripeness classes and their colours, the crop's colours and sizes, and the names of geoms."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import get_args

import numpy as np

from bve_mj.config import RipenessName
from bve_mj.sim import plants
from bve_mj.sim.textures import ripeness_stage

__all__ = [
    "FRUIT_COLOURS",
    "PROBE_CAMERA",
    "RIPENESS",
    "Fruit",
    "SceneInfo",
    "fruit_calyx_name",
    "fruit_geom_name",
]

PROBE_CAMERA = "probe"

"""A free camera (mocap body) with the eye-in-hand camera's intrinsics, for tests and views."""


RIPENESS: tuple[str, ...] = get_args(RipenessName)

"""USDA ripeness classes, least ripe first: green, breaker, turning, pink, light_red, red."""


FRUIT_COLOURS: dict[str, tuple[float, float, float, float]] = {
    "green": (0.48, 0.62, 0.25, 1.0),
    "breaker": (0.58, 0.66, 0.30, 1.0),
    "turning": (0.80, 0.62, 0.31, 1.0),
    "pink": (0.90, 0.58, 0.50, 1.0),
    "light_red": (0.88, 0.33, 0.22, 1.0),
    "red": (0.78, 0.10, 0.06, 1.0),
    "orange": (0.80, 0.62, 0.31, 1.0),
}

"""Mean skin colour of each ripeness class (``orange``: the legacy name of a turning fruit)."""


_UP = np.array([0.0, 0.0, 1.0])


# colours (linear RGB) of the crop's parts
_STEM = (0.31, 0.44, 0.17, 1.0)


_OLD_STEM = (0.42, 0.43, 0.26, 1.0)


_TRUSS = (0.33, 0.47, 0.18, 1.0)


_CALYX = (0.22, 0.42, 0.12, 1.0)


_LEAF = np.array([0.17, 0.39, 0.11])


_TWINE = (0.80, 0.77, 0.66, 1.0)


_LEAF_TOP_M = 2.2  # leaves up to this height above the floor; a foliage wall stands in above


_TEXTURE_VARIANTS = 4  # skins per ripeness class (stages spread over the class's range)


_SKIN_PX = 64  # cube-face size of a skin texture


@dataclass(frozen=True)
class Fruit:
    """A tomato: an ellipsoid in the world (robot base) frame.

    Attributes:
        name: unique; the flesh geom is :func:`fruit_geom_name` of it.
        centre_m: centre [m], (3,).
        radius_m: equatorial (horizontal) semi-axis [m].
        colour: ripeness class, one of :data:`RIPENESS` (or the legacy ``orange``, drawn as
            a turning fruit).
        shape_index: vertical / horizontal semi-axis (< 1 flattened, > 1 elongated).
        truss: index of its truss (0 = the target's), -1 for a scripted fruit.
        index: position on the truss, 0 nearest the stem; -1 for a scripted fruit.
        yaw_rad, tilt_rad: turn about the vertical, then tilt about the turned x axis.
        stage: share of the surface no longer green (None: the middle of its class).
    """

    name: str
    centre_m: np.ndarray
    radius_m: float
    colour: str
    shape_index: float = 1.0
    truss: int = -1
    index: int = -1
    yaw_rad: float = 0.0
    tilt_rad: float = 0.0
    stage: float | None = None

    @property
    def semi_axes_m(self) -> np.ndarray:
        """(r, r, r * shape_index) [m] in the fruit's frame."""
        return np.array([self.radius_m, self.radius_m, self.radius_m * self.shape_index])

    @property
    def rotation(self) -> np.ndarray:
        """R_world_fruit: the fruit frame's axes in the world, (3, 3); z is the stem end."""
        return plants.rotation_zx(self.yaw_rad, self.tilt_rad)

    @property
    def top_m(self) -> np.ndarray:
        """The stem end (where the calyx sits) [m], (3,)."""
        return self.centre_m + self.rotation @ np.array([0.0, 0.0, self.radius_m * self.shape_index])

    @property
    def skin_stage(self) -> float:
        """Share of the surface no longer green: ``stage``, else the middle of the class."""
        return ripeness_stage(self.colour) if self.stage is None else self.stage


@dataclass(frozen=True)
class SceneInfo:
    """Ground truth of a built scene.

    ``distractors`` are all fruit but the target (its truss neighbours and the other
    trusses), each with its ripeness; ``leaves`` counts compound leaves; ``extra`` holds the
    trusses (fruit names from the stem outward), the stems and the light drawn.
    """

    target: Fruit
    distractors: tuple[Fruit, ...]
    leaves: int
    seed: int | None
    extra: dict[str, object] = field(default_factory=dict)

    @property
    def fruits(self) -> tuple[Fruit, ...]:
        return (self.target, *self.distractors)


def fruit_geom_name(name: str) -> str:
    return f"{name}_flesh"


def fruit_calyx_name(name: str) -> str:
    """The geom of a fruit's calyx: a mesh of its own, so that a fruit picked takes its sepals
    with it (:meth:`bve_mj.sim.mujoco_world.MujocoWorld.pick`)."""
    return f"{name}_calyx"
