"""The seeded crop: plants, their trusses and fruit, the target among them, kept clear of
each other and of the camera's view cone where the settings ask."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from bve_mj.config import SceneConfig
from bve_mj.sim import plants
from bve_mj.sim.clearance import _clear_of, _in_view_cone
from bve_mj.sim.foliage import _plant_leaves, _stem_at, _stem_path
from bve_mj.sim.fruit_draw import _draw_other_ripeness, _draw_ripeness, _fruit_sizes, _place_fruit, _stage
from bve_mj.sim.scene_model import _LEAF_TOP_M, _UP, Fruit

__all__: list[str] = []  # used by the other modules of this package only


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
