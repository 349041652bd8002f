"""bve_mj: active monocular 3D fruit localisation with a best-viewpoint estimator (BVE)
and an extended Kalman filter, on a simulated eye-in-hand robot arm.

Importing the package has no side effects (no MUJOCO_GL, no logging or thread settings) and
loads nothing heavy: the names below are imported from their modules on first use
(PEP 562), so ``import bve_mj`` or ``from bve_mj.config import Settings`` does not load
SciPy's optimisers, Pinocchio or MuJoCo.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from bve_mj.campaigns.paper import run_synthetic, run_table
    from bve_mj.config import Settings, describe, load_settings, settings_from_dict
    from bve_mj.config.experiments import EXPERIMENTS, Experiment
    from bve_mj.errors import BveError, ConfigError, EstimationError, PlanningError
    from bve_mj.estimation import Belief, CameraModel, RangeModel, predict, update
    from bve_mj.geometry import camera_rotation, look_at_pose
    from bve_mj.loop.episode import EpisodeResult, ViewRecord, run_episode
    from bve_mj.loop.mujoco import MujocoEpisode, run_mujoco_episode
    from bve_mj.planning import BvePlanner, CirclePlanner, RandomPlanner, ViewPlan, make_planner
    from bve_mj.sim import Scenario, SyntheticWorld

__version__ = "0.1.0"

_EXPORTS: dict[str, str] = {
    **dict.fromkeys(("Settings", "describe", "load_settings", "settings_from_dict"), "bve_mj.config"),
    **dict.fromkeys(("EpisodeResult", "ViewRecord", "run_episode"), "bve_mj.loop.episode"),
    **dict.fromkeys(("BveError", "ConfigError", "EstimationError", "PlanningError"), "bve_mj.errors"),
    **dict.fromkeys(("Belief", "CameraModel", "RangeModel", "predict", "update"), "bve_mj.estimation"),
    **dict.fromkeys(("EXPERIMENTS", "Experiment"), "bve_mj.config.experiments"),
    **dict.fromkeys(("run_synthetic", "run_table"), "bve_mj.campaigns.paper"),
    **dict.fromkeys(("camera_rotation", "look_at_pose"), "bve_mj.geometry"),
    **dict.fromkeys(("MujocoEpisode", "run_mujoco_episode"), "bve_mj.loop.mujoco"),
    **dict.fromkeys(
        ("BvePlanner", "CirclePlanner", "RandomPlanner", "ViewPlan", "make_planner"), "bve_mj.planning"
    ),
    **dict.fromkeys(("Scenario", "SyntheticWorld"), "bve_mj.sim"),
}


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'bve_mj' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_EXPORTS})


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
    "MujocoEpisode",
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
    "run_mujoco_episode",
    "run_synthetic",
    "run_table",
    "settings_from_dict",
    "update",
]
