"""Ground truth for a simulated box detector: the exact bounding box of every ripe fruit the
eye-in-hand camera sees (``detector.kind = "synthetic_boxes"``,
:class:`bve_mj.perception.synthetic_boxes.SyntheticBoxes`).

Each fruit is its ellipsoid (centre, semi-axes, rotation: :class:`~bve_mj.sim.scene_model.Fruit`),
projected exactly by the camera as rendered (its true pose, the site ``camera_optical``, and
its true intrinsics; :func:`~bve_mj.perception.box_geometry.ellipsoid_box`). A fruit is seen
when its box meets the image and at least :data:`VISIBLE_SHARE` of 9 rays from the camera to
its face (its centre and 8 points at 0.7 of its radius around it, across the line of sight)
reach its flesh first: a leaf or a neighbour over most of it hides it from a learned
detector as from the built-in one."""

from __future__ import annotations

import math

import mujoco
import numpy as np

from bve_mj.config import CameraConfig
from bve_mj.perception.box_geometry import ellipsoid_box
from bve_mj.perception.detection import Intrinsics
from bve_mj.sim.arm import CAMERA_NAME, CAMERA_SITE
from bve_mj.sim.scene_model import RIPENESS, SceneInfo, fruit_geom_name

__all__ = ["VISIBLE_SHARE", "ripe_colours", "true_boxes", "visible_share"]

VISIBLE_SHARE = 0.3

"""A fruit gets a box when at least this share of the rays to its face reach it."""

_RENDERED_GROUPS = np.array([1, 1, 1, 0, 0, 0], dtype=np.uint8)  # MuJoCo's default visible groups


def ripe_colours(ripe_class: str | None) -> set[str]:
    """The ripeness classes (fruit colours) a detector taking ``ripe_class`` as its least ripe
    counts as ripe (None: red only; ``orange`` is turning)."""
    least = "red" if ripe_class is None else ("turning" if ripe_class == "orange" else ripe_class)
    out = set(RIPENESS[RIPENESS.index(least) :])
    return out | {"orange"} if "turning" in out else out


def true_boxes(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    info: SceneInfo,
    camera: CameraConfig,
    ripe_class: str | None = None,
) -> np.ndarray:
    """The true bounding boxes (n, 4) (u_min, v_min, u_max, v_max) [px, not clipped] of the
    ripe fruit of ``info`` (of the classes ``ripe_class`` accepts) the eye-in-hand camera sees
    in ``data`` (kinematics done)."""
    site = model.site(CAMERA_SITE).id
    p = data.site_xpos[site].copy()
    R = data.site_xmat[site].reshape(3, 3).copy()  # the paper's camera frame
    intr = Intrinsics.from_camera(camera)
    ripe = ripe_colours(ripe_class)
    boxes = []
    for fruit in info.fruits:
        if fruit.colour not in ripe:
            continue
        Rf = fruit.rotation
        Q_world = Rf @ np.diag(fruit.semi_axes_m**2) @ Rf.T
        box = ellipsoid_box(R.T @ (fruit.centre_m - p), R.T @ Q_world @ R, intr)
        if box is None or box[2] <= 0 or box[3] <= 0 or box[0] >= intr.width_px or box[1] >= intr.height_px:
            continue
        share = visible_share(model, data, p, fruit.centre_m, fruit.radius_m, fruit_geom_name(fruit.name))
        if share >= VISIBLE_SHARE:
            boxes.append(box)
    return np.array(boxes).reshape(-1, 4)


def visible_share(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    p_world_camera: np.ndarray,
    centre_m: np.ndarray,
    radius_m: float,
    geom: str,
) -> float:
    """The share of 9 rays from the camera at ``p_world_camera`` to a fruit's centre and to 8
    points at 0.7 of its radius around it, across the line of sight, that hit its geom
    ``geom`` first (the rendered geom groups only; the camera's own body left out)."""
    try:
        target = model.geom(geom).id
    except KeyError:  # a fruit without its flesh geom: nothing to hide it by
        return 1.0
    d = centre_m - p_world_camera
    rho = float(np.linalg.norm(d))
    if rho <= radius_m:
        return 0.0
    axis = d / rho
    e1 = np.cross(axis, [0.0, 0.0, 1.0])
    e1 = e1 / np.linalg.norm(e1) if np.linalg.norm(e1) > 1e-9 else np.array([0.0, 1.0, 0.0])
    e2 = np.cross(axis, e1)
    angles = np.linspace(0.0, 2.0 * math.pi, 8, endpoint=False)
    points = [centre_m] + [centre_m + 0.7 * radius_m * (math.cos(a) * e1 + math.sin(a) * e2) for a in angles]
    body = int(model.cam_bodyid[model.camera(CAMERA_NAME).id])
    hit = np.zeros(1, dtype=np.int32)
    seen = 0
    for q in points:
        v = q - p_world_camera
        mujoco.mj_ray(model, data, p_world_camera, v / np.linalg.norm(v), _RENDERED_GROUPS, 1, body, hit)
        seen += int(hit[0] == target)
    return seen / len(points)
