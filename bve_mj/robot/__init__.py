"""Robots: descriptions, Pinocchio kinematics of the eye-in-hand camera, look-at IK."""

from bve_mj.robot.description import ROBOTS, RobotDescription, get_robot, models_dir
from bve_mj.robot.ik import IkOptions, IkResult, look_at_ik
from bve_mj.robot.kinematics import CAMERA_FRAME, ArmKinematics, arm_kinematics
from bve_mj.robot.planner import KinematicBvePlanner, Reachability, make_arm_planner

__all__ = [
    "CAMERA_FRAME",
    "ROBOTS",
    "ArmKinematics",
    "IkOptions",
    "IkResult",
    "KinematicBvePlanner",
    "Reachability",
    "RobotDescription",
    "arm_kinematics",
    "get_robot",
    "look_at_ik",
    "make_arm_planner",
    "models_dir",
]
