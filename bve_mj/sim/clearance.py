"""Keeping the crop's parts apart: fruit clear of each other, leaves and stalks out of the
fruit and (where the settings ask) out of the camera's view cone to the target."""

from __future__ import annotations

import math

import numpy as np

from bve_mj.sim import plants
from bve_mj.sim.scene_model import Fruit

__all__: list[str] = []  # used by the other modules of this package only


def _clear_of(fruit: Fruit, others: list[Fruit], margin: float) -> bool:
    S = plants.ellipsoid_shape(fruit.semi_axes_m, fruit.rotation)
    for o in others:
        d = o.centre_m - fruit.centre_m
        dist = float(np.linalg.norm(d))
        if (
            dist
            > fruit.radius_m * max(1.0, fruit.shape_index) + o.radius_m * max(1.0, o.shape_index) + margin
        ):
            continue
        t, _ = plants.contact_distance(S, plants.ellipsoid_shape(o.semi_axes_m, o.rotation), d)
        if dist < t + margin:
            return False
    return True


def _in_view_cone(points: np.ndarray, target: Fruit) -> np.ndarray:
    """Which points lie in the cone in front of the target (robot side, 30° half-angle,
    0.45 m deep) that growers keep clear and the camera looks through."""
    v = np.atleast_2d(points) - target.centre_m
    ahead = -v[:, 0]
    lateral = np.hypot(v[:, 1], v[:, 2])
    r = target.radius_m * max(1.0, target.shape_index)
    return (
        (ahead > -r)
        & (ahead < 0.45)
        & (lateral < r + 0.025 + math.tan(math.radians(30.0)) * np.maximum(ahead, 0))
    )


class _Solids:
    """Fruit as arrays, to test many points against all of them at once."""

    def __init__(self, fruits: list[Fruit]) -> None:
        self.centres = np.array([f.centre_m for f in fruits]).reshape(-1, 3)
        self.R = np.array([f.rotation for f in fruits]).reshape(-1, 3, 3)
        self.axes = np.array([f.semi_axes_m for f in fruits]).reshape(-1, 3)
        self.reach = self.axes.max(axis=1) if len(fruits) else np.zeros(0)

    def inside(self, points: np.ndarray, margin: float) -> np.ndarray:
        """Which points lie inside a fruit grown by ``margin``."""
        p = np.atleast_2d(points)
        d = p[:, None, :] - self.centres[None, :, :]  # (P, F, 3)
        near = np.einsum("pfi,pfi->pf", d, d) < (self.reach + margin) ** 2
        if not near.any():
            return np.zeros(len(p), dtype=bool)
        local = np.einsum("pfi,fij->pfj", d, self.R) / (self.axes + margin)
        return (near & (np.einsum("pfi,pfi->pf", local, local) < 1.0)).any(axis=1)


def _inside_fruit(points: np.ndarray, fruits: list[Fruit] | _Solids, margin: float) -> np.ndarray:
    solids = fruits if isinstance(fruits, _Solids) else _Solids(fruits)
    return solids.inside(points, margin)
