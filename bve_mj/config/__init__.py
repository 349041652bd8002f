"""Settings: frozen, keyword-only dataclasses, validated on construction, loadable from TOML.

The parameters the paper leaves open (Σc, Q, initial P, r_k, HFOV, steps per run) are chosen
here, once, each with its reason in the field's ``why`` metadata. :func:`describe` prints
them beside every result, so a table never travels without the settings that made it.

Units are in the names: ``_m`` metres, ``_rad`` radians, ``_px`` pixels, ``_m2`` square
metres.

Sections by part: :mod:`.sensing` (camera, fruit prior, measurement, filter),
:mod:`.planning` (constraints, planner, protocol, robot), :mod:`.scene` (scene, sensors),
:mod:`.episode` (detector, faults, episode), :mod:`.tracking` (every fruit of a truss);
:mod:`.settings` holds them all, loads and
describes them; the allowed values of every choice are defined once, in :mod:`.fields`.
Each setting lives in one section, the one that owns it.

Presets: the settings whose value depends on the world (the paper's synthetic protocol or
the MuJoCo greenhouse) are left unset by default and take their world's value, written
once in :mod:`.presets`, when a runner resolves them (:meth:`Settings.for_world`).
``Settings.paper()`` and ``Settings.greenhouse()`` are the defaults so resolved; a TOML file
sets only what it changes, and a value it sets holds in both worlds. Keys that moved to the
section owning them are still read, with a warning (:mod:`.moved`).
"""

from __future__ import annotations

from bve_mj.config.detector import DetectorConfig
from bve_mj.config.episode import EpisodeConfig, FaultConfig
from bve_mj.config.fields import (
    ConstraintName,
    DetectorKind,
    FilterKind,
    Formulation,
    FruitsMode,
    FruitType,
    JointLimitSet,
    LossName,
    MeasurementKind,
    OptimiserName,
    OtherTrussesRipeness,
    PlannerKind,
    PlanningModel,
    PriorKind,
    PriorSource,
    RipenessName,
    RobotName,
    StateKind,
    TrussLayout,
    WorldName,
)
from bve_mj.config.moved import MOVED_KEYS
from bve_mj.config.planning import ConstraintConfig, PlannerConfig, ProtocolConfig, RobotConfig
from bve_mj.config.presets import PRESETS, WorldPreset
from bve_mj.config.scene import FRUIT_TYPE_DIAMETER_M, FRUIT_TYPE_SHAPE_INDEX, SceneConfig, SensorConfig
from bve_mj.config.sensing import CameraConfig, FilterConfig, FruitPrior, MeasurementConfig
from bve_mj.config.settings import (
    SECTIONS,
    Settings,
    describe,
    load_settings,
    settings_from_dict,
    settings_to_dict,
    with_overrides,
)
from bve_mj.config.tracking import TrackingConfig

__all__ = [
    "FRUIT_TYPE_DIAMETER_M",
    "FRUIT_TYPE_SHAPE_INDEX",
    "MOVED_KEYS",
    "PRESETS",
    "SECTIONS",
    "CameraConfig",
    "ConstraintConfig",
    "ConstraintName",
    "DetectorConfig",
    "DetectorKind",
    "EpisodeConfig",
    "FaultConfig",
    "FilterConfig",
    "FilterKind",
    "Formulation",
    "FruitPrior",
    "FruitType",
    "FruitsMode",
    "JointLimitSet",
    "LossName",
    "MeasurementConfig",
    "MeasurementKind",
    "OptimiserName",
    "OtherTrussesRipeness",
    "PlannerConfig",
    "PlannerKind",
    "PlanningModel",
    "PriorKind",
    "PriorSource",
    "ProtocolConfig",
    "RipenessName",
    "RobotConfig",
    "RobotName",
    "SceneConfig",
    "SensorConfig",
    "Settings",
    "StateKind",
    "TrackingConfig",
    "TrussLayout",
    "WorldName",
    "WorldPreset",
    "describe",
    "load_settings",
    "settings_from_dict",
    "settings_to_dict",
    "with_overrides",
]
