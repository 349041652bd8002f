"""The greenhouse scene: the arm on a pedestal facing a row of tomato plants.

Built with ``mujoco.MjSpec`` on top of the arm's model (menagerie style: the scene includes
the robot). World frame = the robot base frame, as in the paper: the workspace sphere is
centred at (0, 0, 0.159) m. The plant row runs along y at ``row_x_m``; stems, leaflets and
trusses stand on the far side of the paper's plant wall; tomatoes hang on the robot's side.
The ripe target is red; distractors are unripe green or orange. Everything is seeded.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import mujoco
import numpy as np

from bve_mj.config import CameraConfig, SceneConfig
from bve_mj.robot.kinematics import ArmKinematics
from bve_mj.sim.arm import CAMERA_NAME, R_OPTICAL_MUJOCO, arm_spec

__all__ = [
    "FRUIT_COLOURS",
    "PROBE_CAMERA",
    "Fruit",
    "SceneInfo",
    "build_scene",
    "fruit_geom_name",
    "set_probe_pose",
]

PROBE_CAMERA = "probe"
"""A free camera (mocap body) with the eye-in-hand camera's intrinsics, for tests and views."""

FRUIT_COLOURS: dict[str, tuple[float, float, float, float]] = {
    "red": (0.78, 0.07, 0.05, 1.0),
    "green": (0.42, 0.62, 0.18, 1.0),
    "orange": (0.93, 0.47, 0.08, 1.0),
}
_LEAF = (0.16, 0.42, 0.12, 1.0)
_Q_OPT_MJ = np.zeros(4)
mujoco.mju_mat2Quat(_Q_OPT_MJ, R_OPTICAL_MUJOCO.reshape(9))
_STEM = (0.30, 0.45, 0.16, 1.0)


@dataclass(frozen=True)
class Fruit:
    """A tomato: centre [m] in the world (robot base) frame, radius [m], ripeness colour."""

    name: str
    centre_m: np.ndarray
    radius_m: float
    colour: str


@dataclass(frozen=True)
class SceneInfo:
    """Ground truth of a built scene."""

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


def _quat_z_then_x(yaw: float, roll: float) -> list[float]:
    q = np.zeros(4)
    mujoco.mju_euler2Quat(q, np.array([roll, 0.0, yaw]), "XYZ")
    return [float(x) for x in q]


def _add_fruit(body: mujoco.MjsBody, fruit: Fruit, stem_xy: np.ndarray) -> None:
    c, r = fruit.centre_m, fruit.radius_m
    body.add_geom(
        name=fruit_geom_name(fruit.name),
        type=mujoco.mjtGeom.mjGEOM_SPHERE,
        size=[r, 0, 0],
        pos=c,
        rgba=list(FRUIT_COLOURS[fruit.colour]),
        contype=0,
        conaffinity=0,
        group=1,
    )
    # calyx: a flattened green star-ish cap on top
    body.add_geom(
        name=f"{fruit.name}_calyx",
        type=mujoco.mjtGeom.mjGEOM_ELLIPSOID,
        size=[0.45 * r, 0.45 * r, 0.12 * r],
        pos=c + np.array([0.0, 0.0, 0.93 * r]),
        rgba=[0.20, 0.45, 0.12, 1.0],
        contype=0,
        conaffinity=0,
        group=1,
    )
    # peduncle from the calyx up and back to the stem line (a truss branch)
    top = c + np.array([0.0, 0.0, 1.0 * r])
    joint = np.array([stem_xy[0], stem_xy[1], top[2] + 0.06])
    body.add_geom(
        name=f"{fruit.name}_peduncle",
        type=mujoco.mjtGeom.mjGEOM_CAPSULE,
        fromto=[*top, *joint],
        size=[0.003, 0, 0],
        rgba=list(_STEM),
        contype=0,
        conaffinity=0,
        group=1,
    )


def _sample_fruit_centre(cfg: SceneConfig, rng: np.random.Generator) -> np.ndarray:
    return np.array(
        [rng.uniform(*cfg.target_x_m), rng.uniform(*cfg.target_y_m), rng.uniform(*cfg.target_z_m)]
    )


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

    ``target`` and ``distractors`` override the random draw (for scripted scenes); with
    ``leaves=False`` no leaflets are placed (a clear view).
    """
    cfg = cfg or SceneConfig()
    rng = rng or np.random.default_rng(0)
    spec = arm_spec(kin, camera)
    spec.modelname = "greenhouse"
    spec.option.timestep = 0.002
    world = spec.worldbody
    floor_z = -cfg.pedestal_height_m

    # sky, floor, light
    spec.add_texture(
        name="sky", type=mujoco.mjtTexture.mjTEXTURE_SKYBOX, builtin=mujoco.mjtBuiltin.mjBUILTIN_GRADIENT,
        rgb1=[0.86, 0.90, 0.94], rgb2=[0.55, 0.62, 0.70], width=64, height=64,
    )  # fmt: skip
    spec.add_texture(
        name="ground", type=mujoco.mjtTexture.mjTEXTURE_2D, builtin=mujoco.mjtBuiltin.mjBUILTIN_CHECKER,
        rgb1=[0.82, 0.82, 0.80], rgb2=[0.76, 0.76, 0.74], width=128, height=128,
    )  # fmt: skip
    ground = spec.add_material(name="ground", texrepeat=[8, 8], reflectance=0.05)
    ground.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = "ground"
    world.add_geom(
        name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[4, 4, 0.05], pos=[0, 0, floor_z],
        material="ground", contype=0, conaffinity=0, group=1,
    )  # fmt: skip
    world.add_geom(
        name="pedestal", type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.09, 0.09, cfg.pedestal_height_m / 2],
        pos=[0, 0, floor_z / 2], rgba=[0.35, 0.36, 0.38, 1], contype=0, conaffinity=0, group=1,
    )  # fmt: skip
    intensity = rng.uniform(*cfg.light_intensity)
    sun_dir = np.array([rng.uniform(0.2, 0.6), rng.uniform(-0.4, 0.4), -1.0])
    sun = world.add_light(name="sun", pos=[-0.5, 0.0, 2.5], dir=sun_dir / np.linalg.norm(sun_dir))
    sun.type = mujoco.mjtLightType.mjLIGHT_DIRECTIONAL
    sun.diffuse = [intensity, intensity, 0.95 * intensity]
    sun.specular = [0.1, 0.1, 0.1]
    sun.castshadow = cfg.shadows
    # near clipping plane: MuJoCo's default is 1% of the model extent (centimetres in this
    # scene), which clips a fruit the camera approaches; fix the extent, near plane at 5 mm
    spec.stat.extent = 5.0
    spec.visual.map.znear = 0.001
    spec.visual.headlight.ambient = [0.35, 0.35, 0.35]
    spec.visual.headlight.diffuse = [0.25, 0.25, 0.25]

    # the plant row: stems along y, leaflets around them (behind the fruit plane)
    ys = (np.arange(cfg.plants) - (cfg.plants - 1) / 2) * 0.4
    stems = []
    for i, y in enumerate(ys):
        x = cfg.row_x_m + rng.uniform(-0.02, 0.02)
        stems.append(np.array([x, y]))
        world.add_geom(
            name=f"stem{i}", type=mujoco.mjtGeom.mjGEOM_CAPSULE, size=[0.007, 0, 0],
            fromto=[x, y, floor_z, x + rng.uniform(-0.03, 0.03), y + rng.uniform(-0.03, 0.03), 1.2],
            rgba=list(_STEM), contype=0, conaffinity=0, group=1,
        )  # fmt: skip
    n_leaves = 0
    if leaves:
        for i, (x, y) in enumerate(stems):
            for j in range(cfg.leaves_per_plant):
                z = rng.uniform(-0.3, 1.1)
                yaw = rng.uniform(-math.pi, math.pi)
                # leaflets grow sideways and backwards from the stem, not towards the robot
                offset = 0.06 * np.array([abs(math.cos(yaw)) + 0.2, math.sin(yaw), 0.0])
                shade = rng.uniform(0.8, 1.15)
                world.add_geom(
                    name=f"leaf{i}_{j}", type=mujoco.mjtGeom.mjGEOM_ELLIPSOID,
                    size=[rng.uniform(0.035, 0.06), rng.uniform(0.018, 0.03), 0.003],
                    pos=[x + offset[0], y + offset[1], z], quat=_quat_z_then_x(yaw, rng.uniform(-0.6, 0.6)),
                    rgba=[min(1.0, c * shade) for c in _LEAF[:3]] + [1.0],
                    contype=0, conaffinity=0, group=1,
                )  # fmt: skip
                n_leaves += 1
    # a second row further back, for a greenhouse background
    for i, y in enumerate(ys):
        world.add_geom(
            name=f"back_stem{i}", type=mujoco.mjtGeom.mjGEOM_CAPSULE, size=[0.007, 0, 0],
            fromto=[cfg.row_x_m + 1.0, y + 0.2, floor_z, cfg.row_x_m + 1.0, y + 0.2, 1.2],
            rgba=list(_STEM), contype=0, conaffinity=0, group=1,
        )  # fmt: skip
        world.add_geom(
            name=f"back_foliage{i}", type=mujoco.mjtGeom.mjGEOM_ELLIPSOID, size=[0.12, 0.18, 0.5],
            pos=[cfg.row_x_m + 1.05, y + 0.2, 0.35], rgba=[0.14, 0.36, 0.11, 1.0],
            contype=0, conaffinity=0, group=1,
        )  # fmt: skip

    # fruit: the ripe target and unripe distractors, each on a truss to the nearest stem
    if target is None:
        r = rng.uniform(*cfg.fruit_radius_m)
        target = Fruit("target", _sample_fruit_centre(cfg, rng), r, "red")
    chosen: list[Fruit] = [target]
    if distractors is None:
        made = []
        for k in range(cfg.distractors):
            for _ in range(50):  # rejection: no overlap with fruit already placed
                r = rng.uniform(*cfg.fruit_radius_m)
                centre = target.centre_m + np.array(
                    [rng.uniform(-0.02, 0.05), rng.uniform(-0.25, 0.25), rng.uniform(-0.25, 0.2)]
                )
                if all(np.linalg.norm(centre - f.centre_m) > r + f.radius_m + 0.01 for f in chosen):
                    fruit = Fruit(f"distractor{k}", centre, r, "green" if k % 2 == 0 else "orange")
                    made.append(fruit)
                    chosen.append(fruit)
                    break
        distractors = tuple(made)
    for fruit in (target, *distractors):
        nearest = min(stems, key=lambda s: float(np.linalg.norm(s - fruit.centre_m[:2])))
        _add_fruit(world, fruit, nearest)
    # the probe: a free-floating copy of the eye-in-hand camera
    probe = world.add_body(name="probe_body", mocap=True)
    eye = spec.camera(CAMERA_NAME)
    probe.add_camera(name=PROBE_CAMERA, fovy=eye.fovy, resolution=list(eye.resolution), quat=list(_Q_OPT_MJ))
    info = SceneInfo(target, tuple(distractors), n_leaves, None)
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
