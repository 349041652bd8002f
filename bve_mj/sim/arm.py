"""MuJoCo model of an arm, compiled from the same URDF Pinocchio reads, so the two cannot
drift. ``mujoco.MjSpec`` then adds what URDF cannot say: the eye-in-hand camera and a site
on its optical frame, position actuators with the servos' torque limits, the joint-limit
set in use, visual/collision default classes and a ``home`` keyframe.

For example-robot-data arms the URDF's ``package://`` meshes are resolved to the installed
files; visual meshes (DAE, which MuJoCo cannot read) are dropped and the STL collision
meshes serve for both.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass

import mujoco
import numpy as np

from bve_mj.config import CameraConfig
from bve_mj.errors import ConfigError
from bve_mj.robot.kinematics import ArmKinematics

__all__ = ["CAMERA_NAME", "CAMERA_SITE", "R_OPTICAL_MUJOCO", "ArmModel", "arm_spec", "urdf_for_mujoco"]

CAMERA_NAME = "eye_in_hand"
CAMERA_SITE = "camera_optical"

R_OPTICAL_MUJOCO = np.array([[0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
"""Columns: MuJoCo's camera axes (x right, y up, z backwards) in the paper's camera frame
(x forward, y left, z up)."""

# Position-servo stiffness: the servo's continuous torque at this joint error [rad].
_FULL_TORQUE_ERROR_RAD = 0.05
# Reflected rotor inertia of a geared servo (order of magnitude for 300:1-500:1 gearing)
# [kg m²] and viscous joint damping [N m s/rad]. Without armature the Manipulator-H's
# 19 g end link makes its wrist servo unstable at MuJoCo's 2 ms step.
_ARMATURE = 0.1
_DAMPING = 1.0


def urdf_for_mujoco(kin: ArmKinematics) -> str:
    """The arm's URDF as MuJoCo can read it: meshes resolved, DAE visuals dropped."""
    try:
        root = ET.parse(kin.robot.urdf_path).getroot()
    except (OSError, ET.ParseError) as exc:
        raise ConfigError("robot.urdf", str(kin.robot.urdf_path), f"a readable URDF file ({exc})") from None
    for tag in ("gazebo", "transmission"):
        for el in root.findall(tag):
            root.remove(el)
    prefix = "package://example-robot-data/robots/"

    def readable(el: ET.Element) -> bool:  # a primitive, or a mesh MuJoCo can read
        mesh = el.find("geometry/mesh")
        if mesh is None:
            return True
        name = mesh.get("filename", "")
        if name.startswith(prefix):
            name = str(kin.robot.package_root / name[len(prefix) :])
            mesh.set("filename", name)
        return name.lower().endswith((".stl", ".obj"))

    # one geom set per link: its visuals where MuJoCo can read them all, else its collisions
    for link in root.findall("link"):
        visuals, collisions = link.findall("visual"), link.findall("collision")
        keep_visual = bool(visuals) and all(readable(v) for v in visuals)
        for el in collisions if keep_visual else visuals:
            link.remove(el)
        if not keep_visual:
            for col in collisions:
                if not readable(col):
                    link.remove(col)
    ext = ET.SubElement(root, "mujoco")
    ET.SubElement(ext, "compiler", {"discardvisual": "false", "strippath": "false"})
    # (the visuals are kept deliberately: they are this model's only geometry)
    return ET.tostring(root, encoding="unicode")


@dataclass(frozen=True)
class ArmModel:
    """A compiled arm: the model, and where each arm joint lives in qpos/ctrl."""

    model: mujoco.MjModel
    qpos_adr: np.ndarray
    camera_site_id: int
    camera_id: int


def arm_spec(kin: ArmKinematics, camera: CameraConfig | None = None) -> mujoco.MjSpec:
    """MjSpec of ``kin``'s arm with camera, site, actuators, classes and ``home`` keyframe."""
    camera = camera or CameraConfig()
    try:
        spec = mujoco.MjSpec.from_string(urdf_for_mujoco(kin))
    except ValueError as exc:  # MuJoCo's parser: a URDF Pinocchio accepted but MuJoCo cannot read
        raise ConfigError("robot.urdf", str(kin.robot.urdf_path), f"a URDF MuJoCo can read ({exc})") from None
    spec.modelname = kin.robot.name
    spec.compiler.autolimits = True

    visual = spec.add_default("visual", spec.default)
    visual.geom.contype = 0
    visual.geom.conaffinity = 0
    visual.geom.group = 2
    collision = spec.add_default("collision", spec.default)
    collision.geom.group = 3  # scene builders put contact geoms in this class
    arm = spec.add_default("arm", spec.default)
    arm.joint.armature = _ARMATURE
    arm.joint.damping = [_DAMPING, 0.0, 0.0]

    # joints: arm joints take the limit set in use; any other joint (fingers) is removed
    arm_joints = set(kin.joint_names)
    for j in list(spec.joints):
        if j.name not in arm_joints:
            spec.delete(j)
    for eq in list(spec.equalities):  # mimic joints of removed joints (Panda fingers)
        spec.delete(eq)
    lower, upper = kin.limits.lower, kin.limits.upper
    efforts = kin.model.effortLimit
    for i, name in enumerate(kin.joint_names):
        j = spec.joint(name)
        j.classname = arm  # (a class does not re-apply to an existing joint: set both)
        j.armature, j.damping = _ARMATURE, [_DAMPING, 0.0, 0.0]
        j.range = [lower[i], upper[i]]
        j.limited = mujoco.mjtLimited.mjLIMITED_TRUE
        effort = float(efforts[i]) if math.isfinite(efforts[i]) and efforts[i] > 0 else 50.0
        act = spec.add_actuator(name=f"{name}_servo", target=name)
        act.trntype = mujoco.mjtTrn.mjTRN_JOINT
        act.set_to_position(kp=effort / _FULL_TORQUE_ERROR_RAD, dampratio=1.0)
        act.ctrlrange = [lower[i], upper[i]]
        act.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
        act.forcerange = [-effort, effort]
        act.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE

    # the URDF's geoms serve as the visual model; the arm does not collide with itself
    # (adjacent primitives overlap by construction; the planner keeps the arm clear)
    for g in spec.geoms:
        g.classname = visual
        g.contype, g.conaffinity, g.group = 0, 0, 2

    # gravity compensation on the arm's bodies stands in for the servos' integral action
    for b in spec.bodies:
        if b.name != "world":
            b.gravcomp = 1.0

    # the camera on the body of its parent joint, at the Pinocchio frame placement
    frame = kin.model.frames[kin.camera_frame_id]
    parent_joint = kin.model.names[frame.parentJoint]
    body = spec.joint(parent_joint).parent
    R_opt = frame.placement.rotation
    pos = frame.placement.translation
    site = body.add_site(name=CAMERA_SITE, pos=pos, size=[0.005, 0.005, 0.005])
    site.quat = _quat(R_opt)
    site.group = 4
    cam = body.add_camera(name=CAMERA_NAME, pos=pos)
    cam.quat = _quat(R_opt @ R_OPTICAL_MUJOCO)
    cam.fovy = math.degrees(camera.vfov_rad)
    cam.resolution = [camera.width_px, camera.height_px]

    spec.visual.global_.offwidth = max(camera.width_px, 640)
    spec.visual.global_.offheight = max(camera.height_px, 480)
    # no multisampling: on a CPU renderer it doubles a frame's cost; the camera's own blur
    # (camera.blur_sigma_px, applied by the renderer) softens the edges instead
    spec.visual.quality.offsamples = 0

    key = spec.add_key(name="home")
    key.qpos = list(kin.home)
    key.ctrl = list(kin.home)
    return spec


def compile_arm(kin: ArmKinematics, camera: CameraConfig | None = None) -> ArmModel:
    """Compile :func:`arm_spec` and index the arm joints and the camera."""
    model = arm_spec(kin, camera).compile()
    adr = np.array([model.jnt_qposadr[model.joint(n).id] for n in kin.joint_names])
    return ArmModel(model, adr, model.site(CAMERA_SITE).id, model.camera(CAMERA_NAME).id)


def _quat(R: np.ndarray) -> list[float]:
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.ascontiguousarray(R, dtype=float).reshape(9))
    return [float(x) for x in q]
