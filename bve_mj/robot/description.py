"""Robot descriptions: which URDF, which joints, where the eye-in-hand camera sits.

The Manipulator-H is this project's own model (``models/manipulator_h/``); UR5 and Panda
come from example-robot-data (data only: the robots live under
``site-packages/cmeel.prefix/share/example-robot-data/robots/``). Every arm carries a camera
frame whose x axis is the optical axis (the paper's camera frame).
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path

import numpy as np

from bve_mj.errors import ConfigError

__all__ = [
    "ROBOTS",
    "RobotDescription",
    "example_robot_data_dir",
    "get_robot",
    "models_dir",
]

_PI = math.pi

# Manipulator-H joint ranges (manipulator_h.md): the URDF's conservative ±π/2, or the
# ROBOTIS e-manual's operating ranges.
MANIPULATOR_H_LIMITS: dict[str, tuple[tuple[float, float], ...]] = {
    "urdf": ((-_PI / 2, _PI / 2),) * 6,
    "emanual": (
        (-_PI, _PI),
        (-_PI / 2, _PI / 2),
        (-_PI / 2, 3 * _PI / 4),
        (-_PI, _PI),
        (-_PI / 2, _PI / 2),
        (-_PI, _PI),
    ),
}


@cache
def models_dir() -> Path:
    """The ``models/`` folder: inside the installed package (``bve_mj/models``, which a wheel
    carries; found through :mod:`importlib.resources`), or beside the package in a checkout
    (and an editable install)."""
    from importlib.resources import files

    here = Path(__file__).resolve().parents[2] / "models"
    for c in (Path(str(files("bve_mj") / "models")), here):
        if (c / "manipulator_h" / "manipulator_h.urdf").is_file():
            return c
    raise ConfigError("models", str(here), "the bve_mj models folder (reinstall bve_mj)")


@cache
def example_robot_data_dir() -> Path:
    """example-robot-data's ``robots/`` folder (installed by the example-robot-data wheel)."""
    for entry in sys.path:
        c = Path(entry) / "cmeel.prefix" / "share" / "example-robot-data" / "robots"
        if c.is_dir():
            return c
    raise ConfigError("robot", "example-robot-data", "installed: pip install example-robot-data")


def _transform(xyz: tuple[float, float, float], R: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = xyz
    return T


# A camera on a flange whose normal is the flange z axis: camera x = flange z,
# camera y = flange y, camera z = -flange x.
_R_ZFLANGE_CAMERA = np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])


@dataclass(frozen=True)
class RobotDescription:
    """An arm with an eye-in-hand camera.

    Attributes:
        name: registry name.
        urdf: path relative to its root (``models/`` or example-robot-data's ``robots/``).
        root: "models" or "example-robot-data".
        arm_joints: the actuated joints, base to tip (others are locked at 0).
        camera_parent_frame: the URDF frame the camera is mounted on.
        T_parent_camera: camera pose in that frame (4, 4), camera x = optical axis.
        home: a configuration to start from [rad].
        workspace_centre_m, workspace_radius_m: the paper's sphere model of the reach.
        limit_sets: named joint ranges; "urdf" always means the file's own.
    """

    name: str
    urdf: str
    root: str
    arm_joints: tuple[str, ...]
    camera_parent_frame: str
    T_parent_camera: np.ndarray
    home: tuple[float, ...]
    workspace_centre_m: tuple[float, float, float]
    workspace_radius_m: float
    limit_sets: dict[str, tuple[tuple[float, float], ...]] = field(default_factory=dict)
    mount_note: str = ""

    @property
    def urdf_path(self) -> Path:
        base = models_dir() if self.root == "models" else example_robot_data_dir()
        return base / self.urdf

    @property
    def package_root(self) -> Path:
        """What ``package://example-robot-data/robots/`` resolves to."""
        return example_robot_data_dir()


ROBOTS: dict[str, RobotDescription] = {
    "manipulator_h": RobotDescription(
        name="manipulator_h",
        urdf="manipulator_h/manipulator_h.urdf",
        root="models",
        arm_joints=tuple(f"joint{i}" for i in range(1, 7)),
        camera_parent_frame="camera_link",
        T_parent_camera=np.eye(4),
        home=(0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
        workspace_centre_m=(0.0, 0.0, 0.159),
        workspace_radius_m=0.645,
        limit_sets=dict(MANIPULATOR_H_LIMITS),
        mount_note="camera_link: end_link + (0.0535, 0, 0.0415) m, optical axis = tool x",
    ),
    "ur5": RobotDescription(
        name="ur5",
        urdf="ur_description/urdf/ur5_robot.urdf",
        root="example-robot-data",
        arm_joints=(
            "shoulder_pan_joint",
            "shoulder_lift_joint",
            "elbow_joint",
            "wrist_1_joint",
            "wrist_2_joint",
            "wrist_3_joint",
        ),
        camera_parent_frame="tool0",
        T_parent_camera=_transform((-0.0415, 0.0, 0.042), _R_ZFLANGE_CAMERA),
        home=(0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0),
        workspace_centre_m=(0.0, 0.0, 0.089159),
        workspace_radius_m=0.85,
        mount_note="tool0 + (-0.0415, 0, 0.042) m, optical axis = flange z",
    ),
    "panda": RobotDescription(
        name="panda",
        urdf="panda_description/urdf/panda.urdf",
        root="example-robot-data",
        arm_joints=tuple(f"panda_joint{i}" for i in range(1, 8)),
        camera_parent_frame="panda_link8",
        T_parent_camera=_transform((-0.0415, 0.0, 0.042), _R_ZFLANGE_CAMERA),
        home=(0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785),
        workspace_centre_m=(0.0, 0.0, 0.333),
        workspace_radius_m=0.855,
        mount_note="panda_link8 + (-0.0415, 0, 0.042) m, optical axis = flange z",
    ),
}


def get_robot(name: str) -> RobotDescription:
    """The registered robot ``name``; raises ConfigError listing the choices."""
    if name not in ROBOTS:
        raise ConfigError("robot.name", name, "one of " + ", ".join(ROBOTS))
    return ROBOTS[name]
