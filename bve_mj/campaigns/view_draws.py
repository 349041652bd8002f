"""The calibration's drawn views: one seeded scene of a scenario, compiled and ready to render
from poses the arm reaches (:func:`calibration_scene`), and the directions its views are
drawn from (:func:`draw_direction`). :func:`bve_mj.campaigns.calibration.sample_views` and
the twin views (:mod:`bve_mj.campaigns.twin_views`) draw from the same.

Frames: world (robot base), x away from the robot.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np

__all__ = ["CalibrationScene", "calibration_scene", "draw_direction"]

_DISTANCE_M = (0.12, 0.45)  # camera to fruit centre
_AZIMUTH_DEG = 70.0  # either side of the robot's side of the fruit (-x)
_ELEVATION_DEG = (-35.0, 55.0)


class CalibrationScene(NamedTuple):
    """One seeded scene of a scenario, compiled, with what its views are rendered and detected
    with: the views' random stream, the arm, the scene's truth, the model and its data, the
    arm joints' qpos addresses, the camera, the declared noise and fruit prior, a renderer."""

    rng: np.random.Generator
    kin: Any
    info: Any
    model: Any
    data: Any
    adr: np.ndarray
    intrinsics: Any
    measurement: Any
    fruit: Any
    renderer: Any


def calibration_scene(settings: Any, scene_seed: int) -> CalibrationScene:
    """The scene ``scene_seed`` of ``settings`` as the calibration's views see it (close its
    ``renderer`` when done)."""
    import mujoco

    from bve_mj.perception.detection import Intrinsics
    from bve_mj.robot import arm_kinematics
    from bve_mj.sim.mujoco_world import declared_noise
    from bve_mj.sim.render import OffscreenRenderer
    from bve_mj.sim.scene import build_scene

    scene_ss, view_ss = np.random.SeedSequence(scene_seed).spawn(2)
    rng = np.random.default_rng(view_ss)
    kin = arm_kinematics(settings.robot.name, settings.robot.limit_set)
    spec, info = build_scene(kin, settings.scene, np.random.default_rng(scene_ss), settings.camera)
    model = spec.compile()
    cam = settings.camera
    renderer = OffscreenRenderer(
        model, cam.width_px, cam.height_px, shadows=settings.scene.shadows, blur_sigma_px=cam.blur_sigma_px
    )
    adr = np.array([model.jnt_qposadr[model.joint(n).id] for n in kin.joint_names])
    measurement, fruit = declared_noise(settings)
    intrinsics = Intrinsics.from_camera(cam)
    return CalibrationScene(
        rng, kin, info, model, mujoco.MjData(model), adr, intrinsics, measurement, fruit, renderer
    )


def draw_direction(rng: np.random.Generator) -> tuple[np.ndarray, float]:
    """A drawn view's unit direction fruit → camera (world frame) and distance [m]: azimuth
    within ``_AZIMUTH_DEG`` of the robot's side, elevation and distance in their ranges."""
    az = math.radians(rng.uniform(-_AZIMUTH_DEG, _AZIMUTH_DEG))
    el = math.radians(rng.uniform(*_ELEVATION_DEG))
    rho = rng.uniform(*_DISTANCE_M)
    return np.array([-math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)]), rho
