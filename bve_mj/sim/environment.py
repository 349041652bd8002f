"""The greenhouse around the crop: floor, pipe rails, the neighbouring rows, the sky, and the
lights (sun, sky, backlight, headlight)."""

from __future__ import annotations

import math

import mujoco
import numpy as np

from bve_mj.config import SceneConfig
from bve_mj.sim.crop import _Crop
from bve_mj.sim.scene_model import _LEAF_TOP_M
from bve_mj.sim.textures import foliage_texture, ground_texture

__all__: list[str] = []  # used by the other modules of this package only


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
