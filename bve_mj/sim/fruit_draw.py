"""Drawing each fruit of a truss from the scene settings: ripeness (from the stem outward),
size and shape, and placing it touching its neighbours."""

from __future__ import annotations

import math

import numpy as np

from bve_mj.config import SceneConfig
from bve_mj.errors import ConfigError
from bve_mj.sim import plants
from bve_mj.sim.scene_model import _UP, RIPENESS, Fruit
from bve_mj.sim.textures import ripeness_stage

__all__: list[str] = []  # used by the other modules of this package only


def _check_fruit(fruit: Fruit, what: str) -> None:
    if fruit.colour not in (*RIPENESS, "orange"):
        raise ConfigError(f"{what}.colour", fruit.colour, "one of " + ", ".join((*RIPENESS, "orange")))
    if not (fruit.radius_m > 0.0 and fruit.shape_index > 0.0):
        raise ConfigError(
            f"{what}.radius_m", (fruit.radius_m, fruit.shape_index), "radius and shape index > 0"
        )


def _rank(colour: str) -> int:
    return RIPENESS.index("turning" if colour == "orange" else colour)


def _draw_ripeness(cfg: SceneConfig, rng: np.random.Generator, target_colour: str) -> list[str]:
    """The target truss's classes, index 0 nearest the stem (see ``SceneConfig.ripeness``)."""
    n, t = cfg.fruit_per_truss, cfg.target_index
    if cfg.ripeness:
        return list(cfg.ripeness)
    ranks = [0] * n
    ranks[t] = _rank(target_colour)
    for i in range(t - 1, -1, -1):  # nearer the stem: as ripe or riper
        ranks[i] = min(len(RIPENESS) - 1, ranks[i + 1] + int(rng.integers(0, 2)))
    for i in range(t + 1, n):  # further out: the first 3-4 classes behind, then 0-1 each
        drop = int(rng.choice([3, 4], p=[0.7, 0.3])) if i == t + 1 else int(rng.integers(0, 2))
        ranks[i] = max(0, ranks[i - 1] - drop)
    return [RIPENESS[k] for k in ranks]


def _draw_other_ripeness(cfg: SceneConfig, rng: np.random.Generator, n: int) -> list[str]:
    if cfg.other_trusses_ripeness == "unripe":
        first = int(rng.choice([0, 1, 2], p=[0.45, 0.35, 0.2]))
        steps = [int(rng.integers(0, 2)) for _ in range(n)]
    else:
        first = int(rng.integers(0, len(RIPENESS)))
        steps = [int(rng.integers(1, 3)) for _ in range(n)]
    ranks = [first]
    for i in range(1, n):
        ranks.append(max(0, ranks[-1] - steps[i]))
    return [RIPENESS[k] for k in ranks]


def _stage(colour: str, rng: np.random.Generator) -> float:
    return ripeness_stage(colour, float(rng.uniform()))


def _fruit_sizes(
    cfg: SceneConfig, rng: np.random.Generator, n: int
) -> tuple[list[float], list[float], list[float], list[float]]:
    """Radii (the first fruit largest, ±6 % each), shape indices, yaws and tilts."""
    lo, hi = cfg.radius_range_m
    s_lo, s_hi = cfg.shape_index_range
    base = rng.uniform(lo, hi)
    radii = [float(np.clip(base * (1.0 - 0.025 * i) * rng.uniform(0.94, 1.06), lo, hi)) for i in range(n)]
    shapes = [float(rng.uniform(s_lo, s_hi)) for _ in range(n)]
    yaws = [float(rng.uniform(-math.pi, math.pi)) for _ in range(n)]
    tilts = [float(rng.uniform(0.0, math.radians(8.0))) for _ in range(n)]
    return radii, shapes, yaws, tilts


def _place_fruit(
    rng: np.random.Generator,
    fruits: list[Fruit],
    anchor: int,
    along: np.ndarray,
    side: np.ndarray,
    layout: str,
) -> list[np.ndarray] | None:
    """Centres of a truss's fruit, ``fruits[anchor]``'s kept, the others touching in turn.

    ``along``: horizontal direction of the rachis from the stem; ``side``: horizontal unit
    across it towards the aisle (cluster: even fruit on that side, odd ones behind).
    """
    n = len(fruits)
    shapes = [plants.ellipsoid_shape(f.semi_axes_m, f.rotation) for f in fruits]
    beta0 = math.radians(rng.uniform(8.0, 22.0))
    dbeta = math.radians(rng.uniform(4.0, 10.0))
    gamma = math.radians(rng.uniform(52.0, 59.0))
    zigzag = math.radians(rng.uniform(5.0, 18.0))

    def link(i: int) -> np.ndarray:  # direction from fruit i to fruit i + 1
        beta = min(math.radians(65.0), beta0 + i * dbeta)
        jitter = rng.uniform(-0.17, 0.17)
        c, s = math.cos(jitter), math.sin(jitter)
        a = np.array([c * along[0] - s * along[1], s * along[0] + c * along[1], 0.0])
        d = math.cos(beta) * a - math.sin(beta) * _UP
        if layout == "chain":  # a slight zigzag about the rachis, as fruit on alternate pedicels hang
            d = d + math.tan(zigzag) * (-side if i % 2 == 0 else side)  # the first one behind
        if layout == "cluster":
            d = math.cos(gamma) * d + math.sin(gamma) * (-side if i % 2 == 0 else side)
        return d / np.linalg.norm(d)

    centres: list[np.ndarray | None] = [None] * n
    centres[anchor] = fruits[anchor].centre_m.copy()
    directions = [link(i) for i in range(n - 1)]
    for i in range(anchor, n - 1):
        t, nd = plants.contact_distance(shapes[i], shapes[i + 1], directions[i])
        prev = centres[i]
        assert prev is not None
        centres[i + 1] = prev + (t + rng.uniform(0.0002, 0.0012) / nd) * directions[i]
    for i in range(anchor - 1, -1, -1):
        t, nd = plants.contact_distance(shapes[i], shapes[i + 1], directions[i])
        nxt = centres[i + 1]
        assert nxt is not None
        centres[i] = nxt - (t + rng.uniform(0.0002, 0.0012) / nd) * directions[i]
    out = [c for c in centres if c is not None]
    for j in range(n):
        for k in range(j + 2, n):
            d = out[k] - out[j]
            t, _ = plants.contact_distance(shapes[j], shapes[k], d)
            if np.linalg.norm(d) < t + 0.0003:
                return None
    return out
