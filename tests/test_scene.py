"""The procedural greenhouse: every configuration builds and steps cleanly, trusses are made
of touching fruit ripening from the stem outward, the target stays where the settings put it
and in clear view, scenarios are validated by name, and the same seed gives the same scene."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import mujoco
import numpy as np
import pytest

from bve_mj.config import SceneConfig, load_settings, settings_from_dict
from bve_mj.errors import ConfigError
from bve_mj.robot import arm_kinematics
from bve_mj.sim import plants
from bve_mj.sim.scene import build_scene
from bve_mj.sim.scene_model import RIPENESS, Fruit, SceneInfo, fruit_calyx_name, fruit_geom_name
from bve_mj.sim.textures import RIPENESS_STAGES, cube_directions, fruit_texture, ripeness_stage

REPO = Path(__file__).resolve().parents[1]
SEEDS = range(10, 16)  # six seeds beyond the scenario suite's 0-9 (which compile and step there)
CONFIGS: dict[str, dict[str, object]] = {
    "default": {},
    "cluster": {"truss_layout": "cluster", "fruit_per_truss": 8},
    "cherry": {"fruit_type": "cherry", "fruit_per_truss": 12},
    "beefsteak": {"fruit_type": "beefsteak", "fruit_per_truss": 4},
    "plum": {"fruit_type": "plum", "fruit_per_truss": 6},
    "backlit": {"sun_azimuth_deg": (-20.0, 20.0), "backlight": 0.6, "headlight": True},
    "shadows": {"shadows": True, "leaf_density": 1.5},
    "turning_target": {"target_ripeness": "turning", "target_index": 1, "other_trusses_ripeness": "mixed"},
}


@pytest.fixture(scope="module")
def kin():
    return arm_kinematics("manipulator_h", "emanual")


def _build(kin, cfg: SceneConfig, seed: int, **kw) -> tuple[mujoco.MjModel, SceneInfo]:
    spec, info = build_scene(kin, cfg, np.random.default_rng(seed), **kw)
    return spec.compile(), info


def _gap_m(model: mujoco.MjModel, data: mujoco.MjData, a: Fruit, b: Fruit) -> float:
    """Signed distance between two fruit surfaces (negative: interpenetration), by MuJoCo."""
    ga, gb = (model.geom(fruit_geom_name(f.name)).id for f in (a, b))
    return float(mujoco.mj_geomDistance(model, data, ga, gb, 0.05, None))


def _rank(f: Fruit) -> int:
    return RIPENESS.index("turning" if f.colour == "orange" else f.colour)


def _views_clear(model: mujoco.MjModel, data: mujoco.MjData, info: SceneInfo) -> float:
    """Share of rays from camera positions 0.3 m in front of the target (robot side, within
    25° of straight on) to points of its silhouette that no leaf, stem or other truss stops
    (its own truss's neighbours, pedicels and calyces may: touching fruit are normal)."""
    target = info.target
    truss0 = [f.name for f in info.fruits if f.truss == 0]
    own = {fruit_geom_name(n) for n in truss0} | {fruit_calyx_name(n) for n in truss0} | {"truss0"}
    own_ids = {model.geom(n).id for n in own}
    groups = np.array([1, 1, 0, 1, 1, 1], np.uint8)  # the arm (group 2) is not an occluder
    hit = np.zeros(1, np.int32)
    clear = total = 0
    for az in np.radians([-25, 0, 25]):
        for el in np.radians([-15, 0, 20]):
            cam = target.centre_m + 0.3 * np.array(
                [-math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)]
            )
            for dy, dz in ((0, 0), (0.6, 0), (-0.6, 0), (0, 0.6), (0, -0.6)):
                aim = target.centre_m + target.radius_m * np.array([0.0, dy, dz * target.shape_index])
                v = aim - cam
                mujoco.mj_ray(model, data, cam, v / np.linalg.norm(v), groups, 1, -1, hit)
                clear += int(hit[0] in own_ids)
                total += 1
    return clear / total


@pytest.mark.parametrize("name", list(CONFIGS))
def test_configuration_builds_steps_and_keeps_its_promises(kin, name: str) -> None:
    """For six seeds: compiles, 100 steps with zero warnings; neighbours in a truss touch
    (gap < 3 mm) and no two fruit interpenetrate by more than 1 mm; drawn ripeness falls from
    the stem outward; the target centre lies in the target ranges, in the truss and class
    the settings ask for."""
    cfg = SceneConfig(**CONFIGS[name])  # type: ignore[arg-type]
    lo, hi = cfg.radius_range_m
    s_lo, s_hi = cfg.shape_index_range
    for seed in SEEDS:
        model, info = _build(kin, cfg, seed)
        data = mujoco.MjData(model)
        mujoco.mj_resetDataKeyframe(model, data, model.key("home").id)
        for _ in range(100):
            mujoco.mj_step(model, data)
        assert [w.number for w in data.warning] == [0] * len(data.warning), (name, seed)
        t = info.target
        for axis, (a, b) in enumerate((cfg.target_x_m, cfg.target_y_m, cfg.target_z_m)):
            assert a <= t.centre_m[axis] <= b, (name, seed, t.centre_m)
        assert (t.truss, t.index) == (0, cfg.target_index)
        trusses = info.extra["trusses"]
        assert isinstance(trusses, list) and len(trusses) <= cfg.trusses
        assert trusses[0][cfg.target_index] == "target" and len(trusses[0]) == cfg.fruit_per_truss
        by_name = {f.name: f for f in info.fruits}
        assert len(by_name) == len(info.fruits) == sum(len(tr) for tr in trusses)
        for f in info.fruits:  # sizes as the settings say, all hanging on the robot side of the row
            assert lo <= f.radius_m <= hi and s_lo <= f.shape_index <= s_hi, (name, seed, f)
            assert f.centre_m[0] < cfg.row_x_m, (name, seed, f.name)
        for k, names in enumerate(trusses):
            fruit = [by_name[n] for n in names]
            assert [f.index for f in fruit] == list(range(len(fruit))) and {f.truss for f in fruit} == {k}
            for a, b in itertools.pairwise(fruit):
                gap = _gap_m(model, data, a, b)
                assert -1e-3 < gap < 3e-3, (name, seed, a.name, b.name, gap)
            ranks = [_rank(f) for f in fruit]
            if k == 0:
                tt = cfg.target_index
                assert ranks[tt] == RIPENESS.index(cfg.target_ripeness)
                assert all(ranks[i] >= ranks[i + 1] for i in range(len(ranks) - 1)), (name, seed, ranks)
            else:
                assert all(ranks[i] >= ranks[i + 1] for i in range(len(ranks) - 1)), (name, seed, ranks)
        fruits = list(info.fruits)
        for i, a in enumerate(fruits):
            for b in fruits[i + 1 :]:
                if np.linalg.norm(a.centre_m - b.centre_m) < 2.5 * max(a.radius_m, b.radius_m) * max(
                    1.0, s_hi
                ):
                    assert _gap_m(model, data, a, b) > -1e-3, (name, seed, a.name, b.name)
        if name == "default":
            mujoco.mj_forward(model, data)
            assert _views_clear(model, data, info) >= 0.95, seed
            assert info.leaves > 50
            assert all(_rank(f) <= RIPENESS.index("turning") for f in info.distractors), seed


def test_default_truss_is_realistic(kin) -> None:
    """Round fruit 47-67 mm wide, flattened 0.8-0.95, five to the target's truss; the target
    nearest the stem is the only red fruit, its neighbour turning or less ripe."""
    cfg = SceneConfig()
    assert cfg.radius_range_m == (0.0235, 0.0335) and cfg.shape_index_range == (0.8, 0.95)
    seen = set()
    for seed in range(6):
        _, info = build_scene(kin, cfg, np.random.default_rng(seed))
        truss = [f for f in info.fruits if f.truss == 0]
        assert len(truss) == 5 and info.target.colour == "red" and info.target.index == 0
        assert sum(f.colour in ("red", "light_red") for f in info.fruits) == 1
        seen.add(tuple(f.colour for f in sorted(truss, key=lambda f: f.index)))
    assert len(seen) > 1  # drawn with some randomness


@pytest.mark.parametrize(
    ("scene", "field"),
    [
        ({"fruit_per_truss": 0}, "scene.fruit_per_truss"),
        ({"fruit_per_truss": 4, "target_index": 4}, "scene.target_index"),
        ({"target_index": -1}, "scene.target_index"),
        ({"ripeness": ["red", "purple", "green", "green", "green"]}, "scene.ripeness"),
        ({"ripeness": ["red", "green"]}, "scene.ripeness"),
        ({"ripeness": "red"}, "scene.ripeness"),
        ({"target_ripeness": "ripe"}, "scene.target_ripeness"),
        ({"shape_index": [0.0, 1.0]}, "scene.shape_index"),
        ({"shape_index": [-0.5, 1.0]}, "scene.shape_index"),
        ({"shape_index": [1.2, 0.9]}, "scene.shape_index"),
        ({"fruit_type": "grape"}, "scene.fruit_type"),
        ({"truss_layout": "spiral"}, "scene.truss_layout"),
        ({"trusses": 0}, "scene.trusses"),
        ({"leaf_density": -1.0}, "scene.leaf_density"),
        ({"sun_elevation_deg": [10.0, 95.0]}, "scene.sun_elevation_deg"),
        ({"backlight": -0.1}, "scene.backlight"),
        ({"headlight": "yes"}, "scene.headlight"),
    ],
)
def test_bad_scenario_input_names_the_field(scene: dict[str, object], field: str) -> None:
    with pytest.raises(ConfigError) as err:
        settings_from_dict({"scene": scene})
    assert err.value.field == field
    if field == "scene.ripeness" and "purple" in str(scene):
        assert all(c in str(err.value) for c in RIPENESS)  # the message lists the classes


def test_defaults_follow_the_fruit_type_and_scenarios_load() -> None:
    cherry = settings_from_dict({"scene": {"fruit_type": "cherry"}}).scene
    assert cherry.radius_range_m == (0.0075, 0.015) and cherry.shape_index_range == (0.9, 1.0)
    plum = settings_from_dict({"scene": {"fruit_type": "plum", "shape_index": [1.3, 1.4]}}).scene
    assert plum.radius_range_m == (0.0175, 0.025) and plum.shape_index_range == (1.3, 1.4)
    given = SceneConfig(fruit_type="beefsteak", fruit_radius_m=(0.03, 0.04))
    assert given.radius_range_m == (0.03, 0.04)
    legacy = load_settings(REPO / "examples" / "scenarios" / "occluded_orange_row.toml").scene
    assert legacy.sun_intensity_range == (0.45, 0.6) and legacy.leaf_scale == 1.5
    assert legacy.radius_range_m == (0.03, 0.04)
    full = settings_from_dict(
        {
            "scene": {
                "trusses": 2,
                "fruit_per_truss": 6,
                "target_index": 2,
                "truss_layout": "cluster",
                "ripeness": ["red", "red", "light_red", "pink", "turning", "green"],
                "fruit_type": "cocktail",
                "leaf_density": 0.5,
                "sun_azimuth_deg": [0, 10],
                "sun_elevation_deg": [20, 30],
                "sun_intensity": [0.8, 0.9],
                "sky_intensity": 0.3,
                "backlight": 0.5,
                "shadows": True,
                "headlight": True,
            }
        }
    ).scene
    assert full.ripeness[2] == "light_red" and full.target_index == 2


def test_given_ripeness_and_legacy_distractors(kin) -> None:
    classes = ("red", "red", "light_red", "pink", "turning", "green")
    cfg = SceneConfig(fruit_per_truss=6, target_index=2, ripeness=classes, distractors=3, trusses=3)
    _, info = _build(kin, cfg, 3)
    truss = sorted((f for f in info.fruits if f.truss == 0), key=lambda f: f.index)
    assert tuple(f.colour for f in truss) == classes and info.target.colour == "light_red"
    assert sum(f.truss > 0 for f in info.fruits) == 3  # the other trusses hold 3 fruit in all


def test_scripted_fruit_and_a_clear_view(kin) -> None:
    target = Fruit("target", np.array([0.42, 0.0, 0.2]), 0.034, "red")
    others = (
        Fruit("g", np.array([0.42, -0.09, 0.2]), 0.035, "green"),
        Fruit("o", np.array([0.42, 0.09, 0.2]), 0.03, "orange"),
    )
    model, info = _build(kin, SceneConfig(), 0, target=target, distractors=others)
    assert np.array_equal(info.target.centre_m, target.centre_m) and info.target.radius_m == 0.034
    assert [f.name for f in info.distractors] == ["g", "o"] and info.distractors[1].colour == "orange"
    geom = model.geom(fruit_geom_name("target"))
    assert np.allclose(geom.size, [0.034, 0.034, 0.034])
    _, alone = _build(kin, SceneConfig(), 0, target=target, distractors=())
    assert alone.fruits == (alone.target,)
    # a given target gets its truss drawn around it; leaves=False changes nothing else
    _, with_leaves = _build(kin, SceneConfig(), 5, target=target)
    _, bare = _build(kin, SceneConfig(), 5, target=target, leaves=False)
    assert with_leaves.leaves > 0 and bare.leaves == 0
    assert [f.centre_m.tolist() for f in with_leaves.fruits] == [f.centre_m.tolist() for f in bare.fruits]
    assert with_leaves.target.index == 0 and len(with_leaves.extra["trusses"][0]) == 5  # type: ignore[index]
    with pytest.raises(ConfigError, match=r"target\.colour"):
        build_scene(kin, SceneConfig(), target=Fruit("target", np.zeros(3), 0.03, "purple"))


def test_the_same_seed_gives_the_same_scene(kin) -> None:
    def fingerprint(seed: int) -> list[np.ndarray]:
        model, info = _build(kin, SceneConfig(), seed)
        return [
            model.geom_pos,
            model.geom_size,
            model.geom_rgba,
            model.mesh_vert,
            model.light_dir,
            model.tex_data,
            np.array([f.centre_m for f in info.fruits]),
        ]

    a, b, c = fingerprint(7), fingerprint(7), fingerprint(8)
    assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
    assert not all(x.shape == y.shape and np.array_equal(x, y) for x, y in zip(a, c, strict=True))


def test_contact_distance_matches_mujoco() -> None:
    """The touching distance of two tilted spheroids, against MuJoCo's own distance."""
    rng = np.random.default_rng(0)
    spec = mujoco.MjSpec()
    for name in ("a", "b"):
        spec.worldbody.add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_ELLIPSOID, size=[0.03, 0.03, 0.03])
    model = spec.compile()
    data = mujoco.MjData(model)
    for _ in range(20):
        axes = [np.array([r, r, r * rng.uniform(0.6, 1.6)]) for r in rng.uniform(0.01, 0.05, 2)]
        rots = [plants.rotation_zx(rng.uniform(-3, 3), rng.uniform(0, 0.3)) for _ in range(2)]
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        t, _ = plants.contact_distance(
            *(plants.ellipsoid_shape(a, R) for a, R in zip(axes, rots, strict=True)), d
        )
        for k, (a, R, p) in enumerate(zip(axes, rots, (np.zeros(3), t * d), strict=True)):
            model.geom_size[k] = a
            model.geom_rbound[k] = a.max()
            data.geom_xpos[k] = p
            data.geom_xmat[k] = R.reshape(9)
        assert abs(mujoco.mj_geomDistance(model, data, 0, 1, 0.05, None)) < 2e-4


def test_skins_colour_the_share_of_the_surface_their_class_says() -> None:
    """The share of a skin's surface no longer green (hue below 50°: tan, yellow-orange, pink,
    red; weighted by the texels' solid angle) is the stage it was made for: the USDA class
    boundaries hold."""
    d = cube_directions(64)
    # solid angle of a cube-map texel ~ (1 + s² + t²)^-1.5 = (largest |direction component|)³
    weight = np.abs(d).max(axis=-1) ** 3
    for name, (lo, hi) in RIPENESS_STAGES.items():
        for u in (0.0, 0.5, 1.0):
            stage = ripeness_stage(name, u)
            r, g, b = np.moveaxis(fruit_texture(stage, 1).astype(float).reshape(6, 64, 64, 3), -1, 0)
            hue = np.degrees(np.arctan2(math.sqrt(3.0) * (g - b), 2.0 * r - g - b))
            coloured = hue < 50.0
            share = float((coloured * weight).sum() / weight.sum())
            if name == "red":  # the last of the shoulder turns orange: no longer green either
                assert share > 0.9, (stage, share)
            else:
                assert abs(share - stage) < 0.04 and lo - 0.04 <= share <= hi + 0.04, (name, stage, share)
    red = fruit_texture(ripeness_stage("red"), 0).astype(float)
    assert np.median(red[..., 0] / np.maximum(red[..., 1], 1)) > 4  # deep red
    assert not fruit_texture(0.5, 0).flags.writeable  # shared through the cache
