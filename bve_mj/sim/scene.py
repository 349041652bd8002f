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
fruit are ellipsoid geoms named :func:`fruit_geom_name`."""

from __future__ import annotations

import mujoco
import numpy as np

from bve_mj.config import CameraConfig, SceneConfig
from bve_mj.robot.kinematics import ArmKinematics
from bve_mj.sim import plants
from bve_mj.sim.arm import CAMERA_NAME, R_OPTICAL_MUJOCO, arm_spec
from bve_mj.sim.crop import _draw_crop
from bve_mj.sim.environment import _environment, _lights
from bve_mj.sim.fruit_draw import _check_fruit
from bve_mj.sim.scene_geoms import _add_fruit, _add_mesh_geom, _truss_parts
from bve_mj.sim.scene_model import (
    _CALYX,
    _OLD_STEM,
    _STEM,
    _TRUSS,
    _TWINE,
    PROBE_CAMERA,
    Fruit,
    SceneInfo,
    fruit_calyx_name,
)

__all__ = ["build_scene", "set_probe_pose"]


_Q_OPT_MJ = np.zeros(4)
mujoco.mju_mat2Quat(_Q_OPT_MJ, R_OPTICAL_MUJOCO.reshape(9))
"""The probe camera's orientation in its body: the paper's optical axes in MuJoCo's camera frame."""


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
        for f in truss.fruits:  # each calyx its own geom: a fruit picked takes it along
            _add_mesh_geom(spec, fruit_calyx_name(f.name), _add_fruit(spec, f, made, rng), _CALYX)
        _add_mesh_geom(spec, f"truss{k}", parts, _TRUSS)
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
