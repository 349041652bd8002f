"""The plant's stems (high-wire, lowered and slanted) and compound leaves (petiole and
leaflets), placed clear of the fruit."""

from __future__ import annotations

import math

import numpy as np

from bve_mj.sim import plants
from bve_mj.sim.clearance import _in_view_cone, _Solids
from bve_mj.sim.scene_model import _LEAF, _UP, Fruit

__all__: list[str] = []  # used by the other modules of this package only


def _stem_path(
    ref: np.ndarray,
    tilt: float,
    z_low: float,
    z_gutter: float,
    z_top: float,
    lean: float,
    rng: np.random.Generator,
) -> np.ndarray:
    """A stem through ``ref``: leaning ``tilt`` along y with a slow wobble, zigzagging a few
    mm at nodes 5-8 cm apart; below ``z_low`` it bends over and slants along the row
    (``lean``) down to the gutter, as a lowered high-wire stem does."""
    zs = np.arange(z_low, z_top, rng.uniform(0.05, 0.08))
    zig = rng.uniform(0.0015, 0.003) * np.where(np.arange(len(zs)) % 2 == 0, 1.0, -1.0)
    phase = rng.uniform(0.0, 2.0 * math.pi)
    wobble = 0.01 * (np.sin(zs * 4.0 + phase) - math.sin(ref[2] * 4.0 + phase))
    upper = np.column_stack([ref[0] + zig, ref[1] + math.tan(tilt) * (zs - ref[2]) + wobble, zs])
    run = rng.uniform(0.7, 1.1)
    start = np.array([ref[0], upper[0, 1] - lean * run, z_gutter + 0.06])
    mid = np.array([ref[0], upper[0, 1] - lean * run * 0.4, z_gutter + 0.06 + 0.45 * (z_low - z_gutter)])
    low = np.array([ref[0], upper[0, 1] - lean * run * 0.12, z_gutter + 0.06 + 0.8 * (z_low - z_gutter)])
    lower = plants.smooth_path(np.array([start, mid, low, upper[0], upper[1]]), 4)[:-5]
    return np.vstack([lower, upper])


def _stem_at(path: np.ndarray, z: float) -> np.ndarray:
    upright = path[np.argmax(np.diff(path[:, 2]) > 0.03) :]
    k = int(np.clip(np.searchsorted(upright[:, 2], z), 1, len(upright) - 1))
    a, b = upright[k - 1], upright[k]
    s = (z - a[2]) / max(b[2] - a[2], 1e-9)
    return a + s * (b - a)


def _plant_leaves(
    path: np.ndarray,
    stem_radius: float,
    z_from: float,
    z_to: float,
    density: float,
    target: Fruit,
    fruits: list[Fruit],
    rng: np.random.Generator,
    plant: int,
) -> list[tuple[int, plants.MeshParts, np.ndarray]]:
    """Compound leaves of one plant: one every 5-8 cm / density of stem, phyllotaxis ~137°."""
    out = []
    solids = _Solids(fruits)
    z = z_from + rng.uniform(0.0, 0.06) / max(density, 1e-6)
    azimuth = rng.uniform(-math.pi, math.pi)
    while z < z_to:
        azimuth += math.radians(137.5) + rng.uniform(-0.4, 0.4)
        for turn in (0.0, 2.4, -2.4):
            psi = azimuth + turn
            petiole, mesh = _compound_leaf(_stem_at(path, z), stem_radius, psi, rng, old=z < z_from + 0.3)
            if _in_view_cone(petiole, target).any() or solids.inside(petiole, 0.004).any():
                continue
            parts = plants.MeshParts()
            parts.add(*mesh[0])
            for verts, faces in _clear_leaflets(mesh[1:], target, solids):
                parts.add(verts, faces)
            shade = rng.uniform(0.8, 1.15)
            yellowing = max(0.0, 0.25 - 0.2 * (z - z_from)) * rng.uniform(0.0, 1.0)
            rgb = np.clip(_LEAF * shade + yellowing * np.array([0.25, 0.12, 0.0]), 0.0, 1.0)
            out.append((plant, parts, rgb))
            break
        z += rng.uniform(0.05, 0.08) / max(density, 1e-6)
    return out


def _clear_leaflets(
    leaflets: list[tuple[np.ndarray, np.ndarray]], target: Fruit, solids: _Solids
) -> list[tuple[np.ndarray, np.ndarray]]:
    """The leaflets none of whose vertices lies in the target's view cone or within 3 mm of
    a fruit: every vertex of the leaf tested at once (the same test, point by point, as one
    leaflet at a time; ~10x fewer calls)."""
    if not leaflets:
        return []
    verts = np.concatenate([v for v, _ in leaflets])
    blocked = _in_view_cone(verts, target) | solids.inside(verts, 0.003)
    first = np.cumsum([0, *(len(v) for v, _ in leaflets[:-1])])
    hit = np.logical_or.reduceat(blocked, first)
    return [leaf for leaf, h in zip(leaflets, hit, strict=True) if not h]


def _compound_leaf(
    node: np.ndarray, stem_radius: float, psi: float, rng: np.random.Generator, *, old: bool = False
) -> tuple[np.ndarray, list[tuple[np.ndarray, np.ndarray]]]:
    """A pinnate leaf from the stem at ``node`` heading ``psi``: petiole points, and meshes
    (petiole tube first, then leaflets). ``old`` leaves (the lowest) droop further."""
    length = rng.uniform(0.30, 0.50)
    theta0 = math.radians(rng.uniform(20.0, 40.0) if old else rng.uniform(35.0, 60.0))
    theta1 = math.radians(rng.uniform(50.0, 85.0) if old else rng.uniform(15.0, 60.0))
    curl = rng.uniform(-0.25, 0.25)
    s = np.linspace(0.0, 1.0, 9)
    theta = theta0 - (theta0 + theta1) * s**1.2
    heading = psi + curl * s
    step = length / (len(s) - 1)
    d = np.column_stack([np.cos(theta) * np.cos(heading), np.cos(theta) * np.sin(heading), np.sin(theta)])
    start = node + stem_radius * np.array([math.cos(psi), math.sin(psi), 0.0])
    pts = start + np.vstack([np.zeros(3), np.cumsum(d[:-1] * step, axis=0)])
    meshes = [plants.tube(pts, np.linspace(0.0028, 0.0012, len(pts)), 5)]

    def frame(at: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        k = min(int(at * (len(s) - 1)), len(s) - 2)
        f = at * (len(s) - 1) - k
        p = pts[k] + f * (pts[k + 1] - pts[k])
        tangent = (pts[k + 1] - pts[k]) / np.linalg.norm(pts[k + 1] - pts[k])
        lateral = np.array([-tangent[1], tangent[0], 0.0])  # _UP x tangent
        lateral /= max(float(np.linalg.norm(lateral)), 1e-9)
        return p, tangent, lateral

    pairs = int(rng.integers(2, 5))
    leaflets: list[plants.Leaflet] = []  # made together at the end, in this order
    for k in range(pairs):
        at = 0.30 + 0.58 * k / max(pairs - 1, 1) if pairs > 1 else 0.6
        p, tangent, lateral = frame(at)
        size = rng.uniform(0.05, 0.09) * (0.8 + 0.3 * k / max(pairs - 1, 1))
        for sgn in (1.0, -1.0):
            alpha = math.radians(rng.uniform(45.0, 75.0))
            axis = math.cos(alpha) * tangent + math.sin(alpha) * sgn * lateral - rng.uniform(0.1, 0.4) * _UP
            up = _UP - sgn * rng.uniform(0.2, 0.5) * lateral
            leaflets.append(
                plants.Leaflet(
                    p + 0.004 * axis,
                    axis,
                    up,
                    size * rng.uniform(0.9, 1.1),
                    size * rng.uniform(0.45, 0.6),
                    fold=rng.uniform(0.15, 0.4),
                    droop=rng.uniform(0.05, 0.25),
                )
            )
        if k < pairs - 1 and rng.uniform() < 0.7:  # small leaflets between the pairs
            p2, tangent2, lateral2 = frame(at + 0.29 / max(pairs - 1, 1))
            for sgn in (1.0, -1.0):
                small = rng.uniform(0.018, 0.032)
                axis = tangent2 + 1.4 * sgn * lateral2 - 0.3 * _UP
                leaflets.append(
                    plants.Leaflet(p2, axis, _UP, small, small * 0.55, fold=0.2, droop=0.1, segments=6)
                )
    tip, tangent, _ = frame(1.0)
    size = rng.uniform(0.06, 0.10)
    leaflets.append(
        plants.Leaflet(
            tip, tangent - 0.2 * _UP, _UP, size, size * rng.uniform(0.45, 0.6), fold=0.25, droop=0.15
        )
    )
    return pts, meshes + plants.leaflet_meshes(leaflets)
