"""The greenhouse scene: the arm on a pedestal in the path before a high-wire tomato row.

Built with ``mujoco.MjSpec`` on top of the arm's model (menagerie style: the scene includes
the robot). World frame = the robot base frame, as in the paper: the workspace sphere is
centred at (0, 0, 0.159) m. The plant row runs along y at ``row_x_m``; its partner row (the
other half of the double row) stands 0.45-0.55 m behind it, further rows beyond.

The crop follows docs/greenhouse.md, drawn from the scene's seed within
:class:`~bve_mj.config.SceneConfig`:

* stems 8-15 mm thick, 0.3-0.5 m apart, upright through the ripe zone with a slight lean and
  a zigzag at the nodes, the lowered lower stem slanting down along the row to the gutter;
  a twine from each stem up to the wire;
* compound leaves one every 5-8 cm of stem above the stripped ripe zone: a drooping petiole
  30-50 cm long with 2-4 pairs of ovate, serrated leaflets, a terminal one and small ones
  between; leaves are kept out of the cone in front of the target (growers strip what hides
  the ripe truss) and out of the fruit;
* trusses on the aisle side: a peduncle from the stem, a rachis bending down under the
  fruit, short pedicels with a knuckle, a calyx of 5-6 sepals on each fruit; fruit touch
  (0.2-1.2 mm apart) one after another (``chain``) or alternating on both sides (``cluster``),
  ripening from the stem outward;
* fruit are ellipsoids with semi-axes (r, r, r * shape_index), each turned and tilted a
  little, with a procedural skin (:mod:`bve_mj.sim.textures`) per ripeness class and stage,
  glossy;
* light: the sun (direction and strength drawn from the settings, hard shadows optional),
  the diffuse sky (ambient plus soft light from above), an optional backlight from behind
  the row, the camera's headlight optional.

Thin parts (stems, leaves, trusses, calyces) are meshes made by :mod:`bve_mj.sim.plants`;
fruit are ellipsoid geoms named :func:`fruit_geom_name`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import get_args

import mujoco
import numpy as np

from bve_mj.config import CameraConfig, RipenessName, SceneConfig
from bve_mj.errors import ConfigError
from bve_mj.robot.kinematics import ArmKinematics
from bve_mj.sim import plants
from bve_mj.sim.arm import CAMERA_NAME, R_OPTICAL_MUJOCO, arm_spec
from bve_mj.sim.textures import foliage_texture, fruit_texture, ground_texture, ripeness_stage

__all__ = [
    "FRUIT_COLOURS",
    "PROBE_CAMERA",
    "RIPENESS",
    "Fruit",
    "SceneInfo",
    "build_scene",
    "fruit_geom_name",
    "set_probe_pose",
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

_Q_OPT_MJ = np.zeros(4)
mujoco.mju_mat2Quat(_Q_OPT_MJ, R_OPTICAL_MUJOCO.reshape(9))
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


# --------------------------------------------------------------------------- the crop layout
@dataclass
class _Truss:
    fruits: list[Fruit]
    attach: np.ndarray  # where the peduncle leaves the stem
    plant: int
    side: np.ndarray  # horizontal unit vector towards the aisle, across the rachis
    pedicel_m: list[float]
    layout: str


@dataclass
class _Crop:
    trusses: list[_Truss]
    stems: list[np.ndarray]  # polylines (k, 3), front row
    stem_radii: list[float]
    back_stems: list[np.ndarray]  # partner row
    back_radii: list[float]
    leaves: list[tuple[int, plants.MeshParts, np.ndarray]]  # (plant, mesh, rgb)
    target: Fruit
    others: list[Fruit]
    stem_x_m: float
    back_x_m: float
    z_strip_m: float


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


def _truss_fruit(
    cfg: SceneConfig,
    rng: np.random.Generator,
    truss: int,
    colours: list[str],
    anchor_fruit: Fruit | None,
    anchor: int,
) -> list[Fruit]:
    n = len(colours)
    radii, shapes, yaws, tilts = _fruit_sizes(cfg, rng, n)
    out = []
    for i in range(n):
        name = "target" if (truss == 0 and i == anchor) else f"truss{truss}_fruit{i}"
        if truss == 0 and i == anchor and anchor_fruit is not None:
            out.append(anchor_fruit)
            continue
        out.append(
            Fruit(
                name,
                np.zeros(3),
                radii[i],
                colours[i],
                shapes[i],
                truss,
                i,
                yaws[i],
                tilts[i],
                _stage(colours[i], rng),
            )
        )
    return out


def _with_centres(fruits: list[Fruit], centres: list[np.ndarray]) -> list[Fruit]:
    return [
        Fruit(
            f.name, c, f.radius_m, f.colour, f.shape_index, f.truss, f.index, f.yaw_rad, f.tilt_rad, f.stage
        )
        for f, c in zip(fruits, centres, strict=True)
    ]


def _pedicel_length(radius: float, rng: np.random.Generator) -> float:
    return float(rng.uniform(0.010, 0.024) * np.clip(radius / 0.028, 0.55, 1.0))


def _other_slots(cfg: SceneConfig, rng: np.random.Generator) -> list[tuple[int, int]]:
    """(plant, level) of the other trusses, nearest first: the next truss up on the target's
    plant, the neighbours' at its height, then further up and out (each side first at random)."""
    p = cfg.plants // 2
    order = [
        (0, 1),
        (-1, 0),
        (1, 0),
        (-1, 1),
        (1, 1),
        (0, 2),
        (-2, 0),
        (2, 0),
        (-2, 1),
        (2, 1),
        (-1, 2),
        (1, 2),
    ]
    order += [(0, 3), (-1, 3), (1, 3), (-2, 2), (2, 2)]
    out = []
    flip = rng.uniform() < 0.5
    for dj, level in order:
        if flip and dj != 0:
            dj = -dj
        j = p + dj
        if 0 <= j < cfg.plants and (j, level) not in out:
            out.append((j, level))
    for level in range(4, 12):  # a row of one plant: further trusses up the stem
        out.append((p, level))
    return out


def _draw_crop(
    cfg: SceneConfig,
    rng: np.random.Generator,
    target: Fruit | None,
    distractors: tuple[Fruit, ...] | None,
) -> _Crop:
    # the target's centre first: it depends on the seed and the target ranges only
    centre = np.array(
        [rng.uniform(*cfg.target_x_m), rng.uniform(*cfg.target_y_m), rng.uniform(*cfg.target_z_m)]
    )
    stem_r = float(rng.uniform(0.004, 0.0075))
    scripted = distractors is not None
    anchor = 0 if scripted else cfg.target_index
    # --- the target's truss: its fruit placed touching, around the target
    if target is None:
        colours = ["red"] if scripted else _draw_ripeness(cfg, rng, cfg.target_ripeness)
        fruits = _truss_fruit(cfg, rng, 0, colours, None, anchor)
        t0 = fruits[anchor]
        fruits[anchor] = Fruit(
            "target",
            centre,
            t0.radius_m,
            t0.colour,
            t0.shape_index,
            0,
            anchor,
            t0.yaw_rad,
            t0.tilt_rad,
            t0.stage,
        )
    else:
        colours = [target.colour] if scripted else _draw_ripeness(cfg, rng, target.colour)
        colours[anchor] = target.colour
        given = Fruit(
            target.name,
            np.asarray(target.centre_m, dtype=float),
            target.radius_m,
            target.colour,
            target.shape_index,
            0,
            anchor,
            target.yaw_rad,
            target.tilt_rad,
            target.stage,
        )
        fruits = _truss_fruit(cfg, rng, 0, colours, given, anchor)
    lean = float(rng.choice([-1.0, 1.0]))  # the row's plants lean one way along y
    placed: list[Fruit] = [fruits[anchor]]
    along = side = np.array([-1.0, 0.0, 0.0])
    for attempt in range(40):
        sign = float(rng.choice([-1.0, 1.0]))
        alpha = math.radians(
            rng.uniform(0.0, 15.0 if attempt < 20 else 5.0)
        )  # along the row, not at the camera
        along = np.array([-math.sin(alpha), sign * math.cos(alpha), 0.0])
        side = np.array([-math.cos(alpha), -sign * math.sin(alpha), 0.0])  # across it, towards the aisle
        centres = _place_fruit(
            rng, fruits, anchor, along, side, cfg.truss_layout if attempt < 30 else "chain"
        )
        if centres is not None and max(float(c[0]) for c in centres) < cfg.row_x_m - 0.005:
            placed = _with_centres(fruits, centres)  # all on the robot side of the row
            break
    else:  # pragma: no cover - a straight chain always fits
        anchor = 0
    target = placed[anchor]
    pedicels = [_pedicel_length(f.radius_m, rng) for f in placed]
    back = max(float(f.centre_m[0]) + f.radius_m * max(1.0, f.shape_index) for f in placed)
    stem_x = max(cfg.row_x_m + rng.uniform(-0.01, 0.01), back + stem_r + 0.004)
    node0 = placed[0].top_m + pedicels[0] * _UP
    attach = np.array(
        [
            stem_x - stem_r,
            node0[1] - float(along[1]) * rng.uniform(0.0, 0.04),
            node0[2] + rng.uniform(0.02, 0.05),
        ]
    )

    # --- the plants along the row (the target's in the middle) and their stems
    p_target = cfg.plants // 2
    ys = [float(attach[1])]
    for _ in range(p_target):
        ys.insert(0, ys[0] - rng.uniform(0.30, 0.50))
    for _ in range(cfg.plants - p_target - 1):
        ys.append(ys[-1] + rng.uniform(0.30, 0.50))
    xs = [stem_x + (0.0 if j == p_target else rng.uniform(0.0, 0.015)) for j in range(cfg.plants)]
    radii = [stem_r if j == p_target else float(rng.uniform(0.004, 0.0075)) for j in range(cfg.plants)]
    floor_z = -cfg.pedestal_height_m
    z_gutter = floor_z + 0.42
    z_low = min(float(f.centre_m[2]) - f.radius_m for f in placed) - rng.uniform(0.05, 0.12)
    z_top = floor_z + 2.6
    stems = []
    for j in range(cfg.plants):
        tilt = math.radians(rng.uniform(3.0, 12.0)) * lean
        stems.append(_stem_path(np.array([xs[j], ys[j], attach[2]]), tilt, z_low, z_gutter, z_top, lean, rng))
    trusses = [_Truss(placed, attach, p_target, side, pedicels, cfg.truss_layout)]

    # --- the other trusses: the next one up on the target's plant, then the neighbours'
    all_fruit = list(placed)
    n_other = 0 if scripted else cfg.trusses - 1
    counts = [cfg.fruit_per_truss] * n_other
    if cfg.distractors is not None and not scripted:
        n_other = min(max(1, cfg.trusses - 1), cfg.distractors)
        counts = [
            cfg.distractors // max(n_other, 1) + (1 if k < cfg.distractors % max(n_other, 1) else 0)
            for k in range(n_other)
        ]
    slots = _other_slots(cfg, rng)
    truss_step = float(rng.uniform(0.15, 0.25))
    for k, count in enumerate(counts, start=1):
        for _attempt in range(25):
            if not slots:
                break
            j, level = slots[0]
            fr = _truss_fruit(cfg, rng, k, _draw_other_ripeness(cfg, rng, count), None, 0)
            sign = float(rng.choice([-1.0, 1.0]))
            alpha = math.radians(rng.uniform(0.0, 30.0))
            al = np.array([-math.sin(alpha), sign * math.cos(alpha), 0.0])
            sd = np.array([-math.cos(alpha), -sign * math.sin(alpha), 0.0])
            z_a = float(attach[2]) + level * truss_step + rng.uniform(-0.05, 0.05)
            att = _stem_at(stems[j], z_a) - np.array([radii[j], 0.0, 0.0])
            ped = [_pedicel_length(f.radius_m, rng) for f in fr]
            node0 = att + np.array([0.0, sign * rng.uniform(0.01, 0.04), -rng.uniform(0.01, 0.04)])
            c0 = node0 - (ped[0] + fr[0].radius_m * fr[0].shape_index) * _UP
            fr[0] = _with_centres([fr[0]], [c0])[0]
            cs = _place_fruit(rng, fr, 0, al, sd, cfg.truss_layout)
            if cs is None:
                continue
            gap = rng.uniform(0.004, 0.02)
            shift = (
                att[0]
                - gap
                - max(float(c[0]) + f.radius_m * max(1.0, f.shape_index) for c, f in zip(cs, fr, strict=True))
            )
            shift = min(shift, cfg.row_x_m - 0.005 - max(float(c[0]) for c in cs))  # robot side of the row
            fr = _with_centres(fr, [c + np.array([shift, 0.0, 0.0]) for c in cs])
            blocked = any(_in_view_cone(f.centre_m, target).any() for f in fr)
            if blocked or not all(_clear_of(f, all_fruit, 0.003) for f in fr):
                slots.append(slots.pop(0))
                continue
            trusses.append(_Truss(fr, att, j, sd, ped, cfg.truss_layout))
            all_fruit += fr
            slots.pop(0)
            break

    # scripted extra fruit: each on its own short truss from the nearest stem
    for f in distractors or ():
        j = int(np.argmin([abs(y - f.centre_m[1]) for y in ys]))
        ped = [_pedicel_length(f.radius_m, rng)]
        z_a = float(f.top_m[2] + ped[0] + rng.uniform(0.02, 0.05))
        att = _stem_at(stems[j], z_a) - np.array([radii[j], 0.0, 0.0])
        trusses.append(_Truss([f], att, j, np.array([-1.0, 0.0, 0.0]), ped, "chain"))
        all_fruit.append(f)

    # --- the partner row behind (the other half of the double row): stems and leaves only
    back_x = stem_x + rng.uniform(0.45, 0.55)
    back_stems, back_radii = [], []
    for j in range(cfg.plants):
        ref = np.array([back_x + rng.uniform(-0.01, 0.01), ys[j] + rng.uniform(0.12, 0.28), attach[2]])
        tilt = math.radians(rng.uniform(3.0, 12.0)) * lean
        back_stems.append(_stem_path(ref, tilt, z_low, z_gutter, z_top, lean, rng))
        back_radii.append(float(rng.uniform(0.004, 0.0075)))

    # --- leaves: above the stripped zone, clear of the target's view cone and of the fruit
    z_strip = float(attach[2]) + rng.uniform(0.12, 0.22)
    leaves: list[tuple[int, plants.MeshParts, np.ndarray]] = []
    if cfg.leaf_scale > 0.0:
        for j, (path, radius) in enumerate(zip(stems + back_stems, radii + back_radii, strict=True)):
            density = cfg.leaf_scale * (1.0 if j < cfg.plants else 0.75)
            # each plant stripped at its own pace; the target's to above its truss
            z_from = z_strip if j == p_target else z_strip - rng.uniform(0.0, 0.2)
            leaves += _plant_leaves(
                path, radius, z_from, _LEAF_TOP_M + floor_z, density, target, all_fruit, rng, j
            )
    others = [f for f in all_fruit if f is not target]
    return _Crop(
        trusses, stems, radii, back_stems, back_radii, leaves, target, others, stem_x, back_x, z_strip
    )


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
            for verts, faces in mesh[1:]:
                if _in_view_cone(verts, target).any() or solids.inside(verts, 0.003).any():
                    continue
                parts.add(verts, faces)
            shade = rng.uniform(0.8, 1.15)
            yellowing = max(0.0, 0.25 - 0.2 * (z - z_from)) * rng.uniform(0.0, 1.0)
            rgb = np.clip(_LEAF * shade + yellowing * np.array([0.25, 0.12, 0.0]), 0.0, 1.0)
            out.append((plant, parts, rgb))
            break
        z += rng.uniform(0.05, 0.08) / max(density, 1e-6)
    return out


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
    for k in range(pairs):
        at = 0.30 + 0.58 * k / max(pairs - 1, 1) if pairs > 1 else 0.6
        p, tangent, lateral = frame(at)
        size = rng.uniform(0.05, 0.09) * (0.8 + 0.3 * k / max(pairs - 1, 1))
        for sgn in (1.0, -1.0):
            alpha = math.radians(rng.uniform(45.0, 75.0))
            axis = math.cos(alpha) * tangent + math.sin(alpha) * sgn * lateral - rng.uniform(0.1, 0.4) * _UP
            up = _UP - sgn * rng.uniform(0.2, 0.5) * lateral
            meshes.append(
                plants.leaflet(
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
                meshes.append(
                    plants.leaflet(p2, axis, _UP, small, small * 0.55, fold=0.2, droop=0.1, segments=6)
                )
    tip, tangent, _ = frame(1.0)
    size = rng.uniform(0.06, 0.10)
    meshes.append(
        plants.leaflet(
            tip, tangent - 0.2 * _UP, _UP, size, size * rng.uniform(0.45, 0.6), fold=0.25, droop=0.15
        )
    )
    return pts, meshes


# --------------------------------------------------------------------------- MjSpec assembly
def _add_mesh_geom(
    spec: mujoco.MjSpec,
    name: str,
    parts: plants.MeshParts | tuple[np.ndarray, np.ndarray],
    rgba: tuple[float, ...] | np.ndarray,
    material: str = "",
) -> None:
    verts, faces = parts.arrays() if isinstance(parts, plants.MeshParts) else parts
    mesh = spec.add_mesh(
        name=f"{name}_mesh", uservert=verts.ravel().tolist(), userface=faces.ravel().tolist()
    )
    mesh.inertia = mujoco.mjtMeshInertia.mjMESH_INERTIA_SHELL
    mesh.maxhullvert = 4
    spec.worldbody.add_geom(
        name=name,
        type=mujoco.mjtGeom.mjGEOM_MESH,
        meshname=f"{name}_mesh",
        rgba=list(rgba),
        material=material,
        contype=0,
        conaffinity=0,
        group=1,
    )


def _skin_material(spec: mujoco.MjSpec, fruit: Fruit, made: set[str]) -> str:
    colour = "turning" if fruit.colour == "orange" else fruit.colour
    lo, hi = ripeness_stage(colour, 0.0), ripeness_stage(colour, 1.0)
    u = 0.5 if hi <= lo else (fruit.skin_stage - lo) / (hi - lo)
    variant = int(np.clip(round(u * (_TEXTURE_VARIANTS - 1)), 0, _TEXTURE_VARIANTS - 1))
    name = f"skin_{colour}_{variant}"
    if name not in made:
        stage = ripeness_stage(colour, variant / max(_TEXTURE_VARIANTS - 1, 1))
        tex = fruit_texture(round(stage, 3), variant, _SKIN_PX)
        spec.add_texture(
            name=name,
            type=mujoco.mjtTexture.mjTEXTURE_CUBE,
            width=_SKIN_PX,
            height=6 * _SKIN_PX,
            nchannel=3,
            data=tex.ravel().tolist(),
        )
        mat = spec.add_material(name=name, specular=0.6, shininess=0.85, reflectance=0.0)
        mat.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = name
        made.add(name)
    return name


def _add_fruit(
    spec: mujoco.MjSpec, fruit: Fruit, made: set[str], rng: np.random.Generator
) -> plants.MeshParts:
    """The flesh geom; returns the calyx mesh parts."""
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, fruit.rotation.reshape(9))
    tint = rng.uniform(0.96, 1.02)
    spec.worldbody.add_geom(
        name=fruit_geom_name(fruit.name),
        type=mujoco.mjtGeom.mjGEOM_ELLIPSOID,
        size=list(fruit.semi_axes_m),
        pos=list(fruit.centre_m),
        quat=list(q),
        material=_skin_material(spec, fruit, made),
        rgba=[min(1.0, tint), min(1.0, tint * rng.uniform(0.98, 1.02)), min(1.0, tint), 1.0],
        contype=0,
        conaffinity=0,
        group=1,
    )
    parts = plants.MeshParts()
    sepal = float(np.clip(0.55 * fruit.radius_m + 0.006, 0.008, 0.030))
    parts.extend(plants.calyx(fruit.top_m, fruit.rotation, fruit.semi_axes_m, sepal, rng))
    return parts


def _truss_parts(truss: _Truss, rng: np.random.Generator) -> plants.MeshParts:
    """Peduncle, rachis and pedicels (with their knuckles) of a truss as tubes."""
    parts = plants.MeshParts()
    fruits = truss.fruits
    small = float(np.clip(fruits[0].radius_m / 0.028, 0.55, 1.0))
    nodes = []
    for f, ped in zip(fruits, truss.pedicel_m, strict=True):
        node = f.top_m + ped * _UP
        if truss.layout == "cluster" and len(fruits) > 1:
            node = node + (-0.5 if f.index % 2 == 0 else 0.5) * 0.6 * f.radius_m * truss.side
        nodes.append(node)
    nodes_arr = np.array(nodes)
    # lift the rachis where it would pass through a fruit
    for _ in range(10):
        path = plants.smooth_path(np.vstack([truss.attach, nodes_arr]), 5)
        bad = _inside_fruit(path, fruits, 0.004)
        if not bad.any():
            break
        nodes_arr[:, 2] += 0.004
    out = np.array([-0.012, 0.0, 0.006]) if len(nodes_arr) else np.zeros(3)
    lead = truss.attach + out
    last = nodes_arr[-1] - (nodes_arr[-2] if len(nodes_arr) > 1 else lead)
    tail = nodes_arr[-1] + 0.012 * last / max(float(np.linalg.norm(last)), 1e-9)
    rachis = plants.smooth_path(np.vstack([truss.attach, lead, nodes_arr, tail]), 4)
    radius = 0.0028 * small
    parts.extend(plants.tube(rachis, np.linspace(radius, 0.6 * radius, len(rachis)), 6))
    for f, node in zip(fruits, nodes_arr, strict=True):
        top = f.top_m
        knuckle = top + 0.45 * (node - top) + rng.uniform(-0.002, 0.002, 3)
        pts = np.array(
            [top - 0.002 * _UP, top + 0.25 * (node - top), knuckle, knuckle + 0.08 * (node - top), node]
        )
        rp = 0.0015 * small
        parts.extend(plants.tube(pts, np.array([rp, rp, 1.7 * rp, rp, rp]), 5))
    return parts


def _environment(spec: mujoco.MjSpec, cfg: SceneConfig, crop: _Crop) -> None:
    world = spec.worldbody
    floor_z = -cfg.pedestal_height_m
    T = mujoco.mjtTexture
    spec.add_texture(
        name="sky",
        type=T.mjTEXTURE_SKYBOX,
        builtin=mujoco.mjtBuiltin.mjBUILTIN_GRADIENT,
        rgb1=[0.93, 0.95, 0.97],
        rgb2=[0.66, 0.72, 0.76],
        width=64,
        height=64,
    )
    for name, img, repeat in (
        ("foil", ground_texture("foil"), 6.0),
        ("concrete", ground_texture("concrete"), 4.0),
        ("foliage", foliage_texture(), 1.0),
    ):
        spec.add_texture(
            name=name,
            type=T.mjTEXTURE_2D,
            width=img.shape[1],
            height=img.shape[0],
            nchannel=3,
            data=img.ravel().tolist(),
        )
        mat = spec.add_material(name=name, texrepeat=[repeat, repeat], texuniform=name != "foliage")
        mat.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = name
        if name == "foliage":
            mat.texrepeat = [6.0, 2.0]
            mat.specular = 0.1
    geom = world.add_geom
    G = mujoco.mjtGeom
    geom(
        name="floor",
        type=G.mjGEOM_PLANE,
        size=[6, 6, 1.5],
        pos=[0, 0, floor_z],
        material="foil",
        contype=0,
        conaffinity=0,
        group=1,
    )
    geom(
        name="path",
        type=G.mjGEOM_BOX,
        size=[0.32, 6, 0.002],
        pos=[0, 0, floor_z + 0.002],
        material="concrete",
        contype=0,
        conaffinity=0,
        group=1,
    )
    geom(
        name="pedestal",
        type=G.mjGEOM_BOX,
        size=[0.09, 0.09, cfg.pedestal_height_m / 2],
        pos=[0, 0, floor_z / 2],
        rgba=[0.35, 0.36, 0.38, 1],
        contype=0,
        conaffinity=0,
        group=1,
    )
    for k, x in enumerate((-0.275, 0.275)):  # the heating-pipe rail the platform runs on
        geom(
            name=f"pipe{k}",
            type=G.mjGEOM_CYLINDER,
            size=[0.026, 6.0],
            pos=[x, 0, floor_z + 0.09],
            quat=[0.7071068, 0.7071068, 0, 0],
            rgba=[0.72, 0.73, 0.75, 1],
            contype=0,
            conaffinity=0,
            group=1,
        )
    for k, x in enumerate((crop.stem_x_m, crop.back_x_m)):  # gutters, slabs, wires, canopy
        geom(
            name=f"gutter{k}",
            type=G.mjGEOM_BOX,
            size=[0.09, 6.0, 0.025],
            pos=[x, 0, floor_z + 0.40],
            rgba=[0.58, 0.60, 0.62, 1],
            contype=0,
            conaffinity=0,
            group=1,
        )
        geom(
            name=f"slab{k}",
            type=G.mjGEOM_BOX,
            size=[0.07, 6.0, 0.04],
            pos=[x, 0, floor_z + 0.465],
            rgba=[0.88, 0.88, 0.86, 1],
            contype=0,
            conaffinity=0,
            group=1,
        )
        geom(
            name=f"wire{k}",
            type=G.mjGEOM_CYLINDER,
            size=[0.002, 6.0],
            pos=[x, 0, floor_z + 3.5],
            quat=[0.7071068, 0.7071068, 0, 0],
            rgba=[0.6, 0.6, 0.6, 1],
            contype=0,
            conaffinity=0,
            group=1,
        )
    top = floor_z + _LEAF_TOP_M + 0.1
    canopy = spec.worldbody.add_geom(
        name="canopy",
        type=G.mjGEOM_BOX,
        size=[0.5 * (crop.back_x_m - crop.stem_x_m) + 0.3, 6.0, 0.5 * (floor_z + 3.5 - top)],
        pos=[0.5 * (crop.stem_x_m + crop.back_x_m), 0, 0.5 * (top + floor_z + 3.5)],
        material="foliage",
        contype=0,
        conaffinity=0,
        group=1,
    )
    canopy.castshadow = False
    for k, dx in enumerate((1.4, 1.9, 2.85, 3.35)):  # the next double rows, as walls of foliage
        far = world.add_geom(
            name=f"far_row{k}",
            type=G.mjGEOM_BOX,
            size=[0.18, 6.0, 1.25],
            pos=[crop.stem_x_m + dx, 0, floor_z + 2.1],
            material="foliage",
            contype=0,
            conaffinity=0,
            group=1,
        )
        far.castshadow = False


def _lights(spec: mujoco.MjSpec, cfg: SceneConfig, rng: np.random.Generator) -> dict[str, object]:
    world = spec.worldbody
    azimuth = math.radians(rng.uniform(*cfg.sun_azimuth_deg))
    elevation = math.radians(rng.uniform(*cfg.sun_elevation_deg))
    intensity = float(rng.uniform(*cfg.sun_intensity_range))
    to_sun = np.array(
        [
            math.cos(elevation) * math.cos(azimuth),
            math.cos(elevation) * math.sin(azimuth),
            math.sin(elevation),
        ]
    )
    sun = world.add_light(name="sun", pos=list(0.4 + 3.0 * to_sun), dir=list(-to_sun))
    sun.type = mujoco.mjtLightType.mjLIGHT_DIRECTIONAL
    sun.diffuse = [intensity, intensity, 0.97 * intensity]
    sun.specular = [0.4 * intensity] * 3
    sun.ambient = [0.0, 0.0, 0.0]
    sun.castshadow = cfg.shadows
    sky = world.add_light(name="sky", pos=[0.4, 0.0, 3.0], dir=[0.15, 0.0, -1.0])
    sky.type = mujoco.mjtLightType.mjLIGHT_DIRECTIONAL
    s = cfg.sky_intensity
    sky.diffuse = [0.42 * s, 0.43 * s, 0.45 * s]
    sky.ambient = [0.55 * s, 0.56 * s, 0.58 * s]
    sky.specular = [0.05 * s] * 3
    sky.castshadow = False
    ground = world.add_light(
        name="ground_bounce", pos=[0.4, 0.0, -cfg.pedestal_height_m], dir=[0.0, 0.0, 1.0]
    )
    ground.type = mujoco.mjtLightType.mjLIGHT_DIRECTIONAL  # the white ground foil lights the crop from below
    ground.diffuse = [0.22 * s, 0.23 * s, 0.22 * s]
    ground.specular = [0.0, 0.0, 0.0]
    ground.castshadow = False
    if cfg.backlight > 0.0:
        b = cfg.backlight
        back = world.add_light(name="backlight", pos=[2.5, 0.0, 1.0], dir=[-0.96, 0.0, -0.28])
        back.type = mujoco.mjtLightType.mjLIGHT_DIRECTIONAL
        back.diffuse = [b, 0.98 * b, 0.92 * b]
        back.specular = [0.3 * b] * 3
        back.castshadow = False
    head = spec.visual.headlight
    head.active = int(cfg.headlight)
    head.ambient = [0.05, 0.05, 0.05]
    head.diffuse = [0.35, 0.35, 0.35]
    head.specular = [0.2, 0.2, 0.2]
    return {"sun_direction": (-to_sun).tolist(), "sun_intensity": intensity}


def build_scene(
    kin: ArmKinematics,
    cfg: SceneConfig | None = None,
    rng: np.random.Generator | None = None,
    camera: CameraConfig | None = None,
    *,
    target: Fruit | None = None,
    distractors: tuple[Fruit, ...] | None = None,
    leaves: bool = True,
) -> tuple[mujoco.MjSpec, SceneInfo]:
    """The scene's MjSpec and its ground truth.

    ``target`` and ``distractors`` override the random draw (for scripted scenes): a given
    target keeps its centre, size and class and gets its truss drawn around it; given
    distractors replace every other fruit (each hangs from the nearest stem). With
    ``leaves=False`` no leaves are placed (a clear view); the rest of the scene is the same.
    """
    cfg = cfg or SceneConfig()
    rng = rng or np.random.default_rng(0)
    if target is not None:
        _check_fruit(target, "target")
    for f in distractors or ():
        _check_fruit(f, "distractors")
    crop = _draw_crop(cfg, rng, target, distractors)
    spec = arm_spec(kin, camera)
    spec.modelname = "greenhouse"
    spec.option.timestep = 0.002
    # near clipping plane: MuJoCo's default is 1% of the model extent (centimetres in this
    # scene), which clips a fruit the camera approaches; fix the extent, near plane at 5 mm
    spec.stat.extent = 5.0
    spec.visual.map.znear = 0.001
    _environment(spec, cfg, crop)
    light = _lights(spec, cfg, rng)

    for j, (path, radius) in enumerate(
        zip(crop.stems + crop.back_stems, crop.stem_radii + crop.back_radii, strict=True)
    ):
        row = "stem" if j < len(crop.stems) else "back_stem"
        k = j if j < len(crop.stems) else j - len(crop.stems)
        lowered = path[:, 2] < crop.z_strip_m - 0.35
        parts = plants.MeshParts()
        parts.extend(plants.tube(path, radius, 7))
        _add_mesh_geom(spec, f"{row}{k}", parts, _OLD_STEM if lowered.mean() > 0.5 else _STEM)
        spec.worldbody.add_geom(
            name=f"{row}{k}_twine",
            type=mujoco.mjtGeom.mjGEOM_CAPSULE,
            size=[0.0008, 0, 0],
            fromto=[*path[-1], path[-1][0], path[-1][1], -cfg.pedestal_height_m + 3.5],
            rgba=list(_TWINE),
            contype=0,
            conaffinity=0,
            group=1,
        )
    made: set[str] = set()
    for k, truss in enumerate(crop.trusses):
        parts = _truss_parts(truss, rng)
        calyces = plants.MeshParts()
        for f in truss.fruits:
            calyces.extend(_add_fruit(spec, f, made, rng).arrays())
        _add_mesh_geom(spec, f"truss{k}", parts, _TRUSS)
        _add_mesh_geom(spec, f"truss{k}_calyces", calyces, _CALYX)
    n_leaves = 0
    if leaves:
        for i, (plant, parts, rgb) in enumerate(crop.leaves):
            _add_mesh_geom(spec, f"leaf{plant}_{i}", parts, (*rgb, 1.0))
            n_leaves += 1
    # the probe: a free-floating copy of the eye-in-hand camera
    probe = spec.worldbody.add_body(name="probe_body", mocap=True)
    eye = spec.camera(CAMERA_NAME)
    probe.add_camera(name=PROBE_CAMERA, fovy=eye.fovy, resolution=list(eye.resolution), quat=list(_Q_OPT_MJ))
    extra: dict[str, object] = {
        "trusses": [[f.name for f in t.fruits] for t in crop.trusses],
        "stems_xy_m": [
            p[np.argmin(np.abs(p[:, 2] - crop.target.centre_m[2]))][:2].tolist() for p in crop.stems
        ],
        "strip_height_m": crop.z_strip_m,
        **light,
    }
    info = SceneInfo(crop.target, tuple(crop.others), n_leaves, None, extra)
    return spec, info


def set_probe_pose(
    model: mujoco.MjModel, data: mujoco.MjData, p_world: np.ndarray, R_world_camera: np.ndarray
) -> None:
    """Put the probe camera at ``p_world`` with the paper's camera axes ``R_world_camera``."""
    mocap = model.body("probe_body").mocapid[0]
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.ascontiguousarray(R_world_camera, dtype=float).reshape(9))
    data.mocap_pos[mocap] = p_world
    data.mocap_quat[mocap] = q
