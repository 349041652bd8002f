"""bve_mj: active monocular 3D fruit localisation with a best-viewpoint estimator (BVE)
and an extended Kalman filter, on a simulated eye-in-hand robot arm.

Importing the package has no side effects (no MUJOCO_GL, no logging or thread settings).
"""

from bve_mj.config import Settings, describe, load_settings, settings_from_dict
from bve_mj.episode import EpisodeResult, ViewRecord, run_episode
from bve_mj.errors import BveError, ConfigError, EstimationError, PlanningError
from bve_mj.estimation import Belief, CameraModel, RangeModel, predict, update
from bve_mj.experiments import EXPERIMENTS, Experiment, run_synthetic, run_table
from bve_mj.geometry import camera_rotation, look_at_pose
from bve_mj.planning import BvePlanner, CirclePlanner, RandomPlanner, ViewPlan, make_planner
from bve_mj.sim import Scenario, SyntheticWorld

__version__ = "0.1.0"

__all__ = [
    "EXPERIMENTS",
    "Belief",
    "BveError",
    "BvePlanner",
    "CameraModel",
    "CirclePlanner",
    "ConfigError",
    "EpisodeResult",
    "EstimationError",
    "Experiment",
    "PlanningError",
    "RandomPlanner",
    "RangeModel",
    "Scenario",
    "Settings",
    "SyntheticWorld",
    "ViewPlan",
    "ViewRecord",
    "__version__",
    "camera_rotation",
    "describe",
    "load_settings",
    "look_at_pose",
    "make_planner",
    "predict",
    "run_episode",
    "run_synthetic",
    "run_table",
    "settings_from_dict",
    "update",
]
