"""Settings: frozen, keyword-only dataclasses, validated on construction, loadable from TOML.

The parameters the paper leaves open (Σc, Q, initial P, r_k, HFOV, steps per run) are chosen
here, once, each with its reason in the field's ``why`` metadata. :func:`describe` prints
them beside every result, so a table never travels without the settings that made it.

Units are in the names: ``_m`` metres, ``_rad`` radians, ``_px`` pixels, ``_m2`` square
metres.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import sys
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, get_args

import numpy as np

from bve_mj.errors import ConfigError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

__all__ = [
    "CameraConfig",
    "ConstraintConfig",
    "DetectorConfig",
    "EpisodeConfig",
    "FaultConfig",
    "FilterConfig",
    "FilterKind",
    "FruitPrior",
    "LossName",
    "MeasurementConfig",
    "MeasurementKind",
    "OptimiserName",
    "PlannerConfig",
    "PlannerKind",
    "PlanningModel",
    "PriorSource",
    "ProtocolConfig",
    "RobotConfig",
    "RobotName",
    "SceneConfig",
    "SensorConfig",
    "Settings",
    "StateKind",
    "WorldName",
    "describe",
    "load_settings",
    "settings_from_dict",
    "settings_to_dict",
]

MeasurementKind = Literal["auto", "range", "camera"]
FilterKind = Literal["ekf", "ukf"]
StateKind = Literal["auto", "centre", "centre_radius"]
WorldName = Literal["synthetic", "mujoco"]
LossName = Literal["dispersion", "max_eigenvalue"]
OptimiserName = Literal["slsqp", "trust-constr"]
PlanningModel = Literal["paper", "consistent"]
PlannerKind = Literal["bve", "random", "circle"]
PriorSource = Literal["auto", "filter", "views"]
RobotName = Literal["manipulator_h", "ur5", "panda"]
Formulation = Literal["joint", "cartesian"]


def _why(text: str, unit: str = "") -> dict[str, str]:
    return {"why": text, "unit": unit}


# --------------------------------------------------------------------------- validation
MAX_MAGNITUDE = 1e9
"""No real setting is larger than this in magnitude (lengths in m, angles, variances, weights):
a larger one is a typo, and squaring or sampling it overflows."""


def _number(section: str, name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
        raise ConfigError(f"{section}.{name}", value, "a real number")
    try:
        v = float(value)
    except OverflowError:
        v = math.inf
    if not math.isfinite(v) or abs(v) > MAX_MAGNITUDE:
        raise ConfigError(
            f"{section}.{name}", value, f"a finite real number of magnitude <= {MAX_MAGNITUDE:g}"
        )
    return v


def _positive(section: str, name: str, value: Any) -> None:
    if _number(section, name, value) <= 0.0:
        raise ConfigError(f"{section}.{name}", value, "a number > 0")


def _non_negative(section: str, name: str, value: Any) -> None:
    if _number(section, name, value) < 0.0:
        raise ConfigError(f"{section}.{name}", value, "a number >= 0")


def _between(section: str, name: str, value: Any, lo: float, hi: float) -> None:
    """lo <= value <= hi: a number outside is no measurement of this world (a tiny σ collapses
    the filter's covariance, a huge one means nothing)."""
    v = _number(section, name, value)
    if not lo <= v <= hi:
        raise ConfigError(f"{section}.{name}", value, f"a number in [{lo:g}, {hi:g}]")


def _open_interval(section: str, name: str, value: Any, lo: float, hi: float, text: str) -> None:
    v = _number(section, name, value)
    if not lo < v < hi:
        raise ConfigError(f"{section}.{name}", value, text)


MAX_COUNT = 1_000_000
"""No count setting is larger than this (its own bound, where it has one, is tighter): a larger
one is a typo that would run for ever."""


def _positive_int(section: str, name: str, value: Any, high: int = MAX_COUNT) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not 1 <= value <= high:
        raise ConfigError(f"{section}.{name}", value, f"an integer in [1, {high}]")


def _choice(section: str, name: str, value: Any, literal: Any) -> None:
    allowed = get_args(literal)
    if value not in allowed:
        raise ConfigError(f"{section}.{name}", value, "one of " + ", ".join(map(str, allowed)))


def _vector3(section: str, name: str, value: Any) -> tuple[float, float, float]:
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ConfigError(f"{section}.{name}", value, "three real numbers") from None
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise ConfigError(f"{section}.{name}", value, "three finite real numbers")
    return (float(arr[0]), float(arr[1]), float(arr[2]))


# --------------------------------------------------------------------------- sections
@dataclass(frozen=True, kw_only=True)
class CameraConfig:
    """The eye-in-hand camera's image geometry (pinhole, square pixels)."""

    hfov_rad: float = field(
        default=math.radians(69.0),
        metadata=_why("OAK-1, the camera the authors used on this arm: 69 deg horizontal", "rad"),
    )
    width_px: int = field(default=640, metadata=_why("OAK-1 preview resolution", "px"))
    height_px: int = field(default=480, metadata=_why("OAK-1 preview resolution", "px"))
    blur_sigma_px: float = field(
        default=0.5,
        metadata=_why(
            "the lens and sensor's point spread (Gaussian sigma) applied to every rendered image: "
            "edges blend over a pixel or two as a real camera's do. It replaces the renderer's "
            "multisample anti-aliasing, which doubles the cost of a frame on a CPU (25 -> 12 ms); "
            "0 = hard pixel edges",
            "px",
        ),
    )

    def __post_init__(self) -> None:
        _open_interval("camera", "hfov_rad", self.hfov_rad, 0.0, math.pi, "a number in (0, pi)")
        _positive_int("camera", "width_px", self.width_px, 8192)
        _positive_int("camera", "height_px", self.height_px, 8192)
        if not 0.0 <= _number("camera", "blur_sigma_px", self.blur_sigma_px) <= 5.0:
            raise ConfigError("camera.blur_sigma_px", self.blur_sigma_px, "a number in [0, 5]")

    @property
    def focal_px(self) -> float:
        """Focal length [px] from the horizontal field of view."""
        return 0.5 * self.width_px / math.tan(0.5 * self.hfov_rad)

    @property
    def vfov_rad(self) -> float:
        """Vertical field of view [rad]."""
        return 2.0 * math.atan(0.5 * self.height_px / self.focal_px)


@dataclass(frozen=True, kw_only=True)
class FruitPrior:
    """What the estimator assumes of a tomato (it never knows the true radius)."""

    radius_m: float = field(
        default=0.035,
        metadata=_why("r_k: middle of greenhouse tomato radii 25-45 mm", "m"),
    )
    radius_spread_rel: float = field(
        default=0.15,
        metadata=_why(
            "the true radius is known only to +-15% (uniform): sigma = 0.15/sqrt(3) = 8.7% of range"
        ),
    )

    shape_spread_rel: float = field(
        default=0.0,
        metadata=_why(
            "non-spherical fruit: the apparent radius varies over viewing directions by +-this share "
            "(uniform; e.g. 0.1 for a 1 : 1 : 0.8 spheroid), added to the range variance; 0 = spheres"
        ),
    )

    shape_index: float = field(
        default=1.0,
        metadata=_why(
            "the shape index (height / width) the detector's spheroid fit starts from and is held "
            "to where a view cannot see it (along the fruit's axis)"
        ),
    )

    def __post_init__(self) -> None:
        _positive("fruit", "radius_m", self.radius_m)
        if not (isinstance(self.shape_index, (int, float)) and 0.4 <= self.shape_index <= 2.5):
            raise ConfigError("fruit.shape_index", self.shape_index, "a number in [0.4, 2.5]")
        for name in ("radius_spread_rel", "shape_spread_rel"):
            value = getattr(self, name)
            _non_negative("fruit", name, value)
            if value >= 1.0:
                raise ConfigError(f"fruit.{name}", value, "a number in [0, 1)")

    @classmethod
    def for_scene(cls, scene: SceneConfig) -> FruitPrior:
        """What the estimator assumes of a fruit of ``scene``'s type: the middle of its radius
        range ± half its width, the middle of its shape-index range, and a shape spread of
        half the largest departure of its shape index from 1 (a spheroid looks up to that
        much larger or smaller than its equator)."""
        lo, hi = scene.radius_range_m
        s_lo, s_hi = scene.shape_index_range
        return cls(
            radius_m=0.5 * (lo + hi),
            radius_spread_rel=min((hi - lo) / (hi + lo), 0.99),
            shape_spread_rel=min(0.5 * max(abs(1.0 - s_lo), abs(1.0 - s_hi)), 0.99),
            shape_index=min(max(0.5 * (s_lo + s_hi), 0.4), 2.5),
        )

    @property
    def size_spread_rel(self) -> float:
        """Standard deviation of the apparent size's relative error from the unknown radius and
        shape: uniform ±s each, s/√3, combined in quadrature."""
        return math.hypot(self.radius_spread_rel, self.shape_spread_rel) / math.sqrt(3.0)


@dataclass(frozen=True, kw_only=True)
class MeasurementConfig:
    """What the filter measures, and the camera-frame covariance Σc it measures it with.

    Σc is derived from the camera, not invented (see :meth:`Settings.sigma_c_m2`): at the
    reference range ρ the lateral σ is ρ·σ_px/f, and the range σ combines the unknown
    true radius with the pixel error of the apparent radius. ``sigma_c_m2`` overrides the
    derivation with an explicit 3x3 (or diagonal) covariance in the camera frame.
    """

    kind: MeasurementKind = field(
        default="auto",
        metadata=_why(
            "auto: range in the synthetic world (the paper's EKF), camera (bearing + range) in the "
            "rendered closed loop, where range alone cannot recover from the unknown fruit radius"
        ),
    )
    centre_sigma_px: float = field(
        default=1.0,
        metadata=_why("blob-centre error: sub-pixel fit plus segmentation bias and calibration", "px"),
    )
    radius_sigma_px: float = field(
        default=0.5, metadata=_why("apparent-radius error of a circle fit to the blob edge", "px")
    )
    reference_range_m: float = field(
        default=1.0, metadata=_why("the protocol's l_dist: Σc is taken at 1 m", "m")
    )
    sigma_c_m2: tuple[tuple[float, ...], ...] | None = field(
        default=None, metadata=_why("explicit Σc (camera frame, x = depth); None derives it", "m^2")
    )
    noise_model: str = field(
        default="default",
        metadata=_why(
            "with the radius in the state (filter.state): the detector's calibrated noise, default "
            "(shipped) or a JSON file from bve-mj calibrate; centre_sigma_px and radius_sigma_px "
            "are then not used"
        ),
    )

    def __post_init__(self) -> None:
        _choice("measurement", "kind", self.kind, MeasurementKind)
        if not isinstance(self.noise_model, str) or not self.noise_model.strip():
            raise ConfigError("measurement.noise_model", self.noise_model, "default or a JSON file path")
        _between("measurement", "centre_sigma_px", self.centre_sigma_px, 1e-3, 1e3)
        _between("measurement", "radius_sigma_px", self.radius_sigma_px, 1e-3, 1e3)
        _between("measurement", "reference_range_m", self.reference_range_m, 0.01, 100.0)
        if self.sigma_c_m2 is not None:
            object.__setattr__(self, "sigma_c_m2", _covariance("measurement.sigma_c_m2", self.sigma_c_m2))


def _covariance(name: str, value: Any) -> tuple[tuple[float, ...], ...]:
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ConfigError(name, value, "a 3x3 symmetric positive-definite matrix or 3 variances") from None
    if arr.shape == (3,):
        arr = np.diag(arr)
    if arr.shape != (3, 3) or not np.all(np.isfinite(arr)) or not np.allclose(arr, arr.T):
        raise ConfigError(name, value, "a 3x3 symmetric positive-definite matrix or 3 variances")
    try:
        np.linalg.cholesky(arr)
    except np.linalg.LinAlgError:
        raise ConfigError(name, value, "a positive-definite matrix (all eigenvalues > 0)") from None
    return tuple(tuple(float(x) for x in row) for row in arr)


@dataclass(frozen=True, kw_only=True)
class FilterConfig:
    """The filter: EKF or UKF over the fruit's state; static fruit (F = I), process noise Q,
    prior P0, optional NIS gating."""

    kind: FilterKind = field(
        default="ekf",
        metadata=_why("ekf (the paper's), or ukf (unscented: no Jacobians, sigma points through h)"),
    )
    state: StateKind = field(
        default="auto",
        metadata=_why(
            "centre: the paper's 3-D state, the range from the apparent size with the radius the prior "
            "assumes; centre_radius: the fruit's radius in the state too, measured as bearing and "
            "apparent angular size (calibration biases too, when the sensor declares them); auto: "
            "centre in the synthetic world (the paper's table), centre_radius in MuJoCo"
        ),
    )
    iterations: int | None = field(
        default=None,
        metadata=_why(
            "linearisations per update (1 = the EKF or UKF; more = the iterated EKF, which linearises "
            "again at the updated mean, or the UKF's posterior linearisation: a bearing seen from a "
            "prior 5 cm off along the ray is otherwise fused 1-2 mm off the ray it measured). None: "
            "1 for the centre state (the paper's), 10 with the radius in the state"
        ),
    )

    @property
    def ekf_iterations(self) -> int:
        """``iterations`` with None resolved for the state."""
        if self.iterations is not None:
            return self.iterations
        return 10 if self.state == "centre_radius" else 1

    process_sigma_m: float = field(
        default=0.0,
        metadata=_why(
            "Q = sigma^2 I per step; 0: the fruit is static and the synthetic world has no model "
            "error (1 mm made the camera-mode filter conservative, NEES 1.7, and twice as wrong)",
            "m",
        ),
    )
    initial_sigma_m: float = field(
        default=0.15 / math.sqrt(3.0),
        metadata=_why("P0: std of the protocol's U[-0.15, 0.15] m initial error per axis", "m"),
    )
    gate_probability: float | None = field(
        default=None,
        metadata=_why("NIS gate (chi-square probability); off in the paper's Gaussian protocol"),
    )

    reset_after_rejections: int = field(
        default=3,
        metadata=_why(
            "with gating: when this many measurements in a row are gated out but agree with each "
            "other, the belief had locked onto something wrong (a false detection fused early): "
            "it is reopened to P0 and they are fused"
        ),
    )

    def __post_init__(self) -> None:
        _choice("filter", "kind", self.kind, FilterKind)
        _choice("filter", "state", self.state, StateKind)
        if self.iterations is not None:
            _positive_int("filter", "iterations", self.iterations, 100)
            if self.iterations > 100:
                raise ConfigError("filter.iterations", self.iterations, "an integer in [1, 100] or none")
        _non_negative("filter", "process_sigma_m", self.process_sigma_m)
        _positive("filter", "initial_sigma_m", self.initial_sigma_m)
        _positive_int("filter", "reset_after_rejections", self.reset_after_rejections, 100)
        if self.gate_probability is not None:
            _open_interval(
                "filter",
                "gate_probability",
                self.gate_probability,
                0.0,
                1.0,
                "a number in (0, 1) or none",
            )


@dataclass(frozen=True, kw_only=True)
class ConstraintConfig:
    """The paper's constraint parameters (eqs. 14-21)."""

    workspace_centre_m: tuple[float, float, float] = field(
        default=(0.0, 0.0, 0.159),
        metadata=_why("m: Manipulator-H joint-2 axis on joint-1 axis (eq. 14)", "m"),
    )
    workspace_radius_m: float = field(
        default=0.645, metadata=_why("r_m: the arm's reach from m, rounded down (eq. 14)", "m")
    )
    cone_fov_rad: float | None = field(
        default=None,
        metadata=_why("field-of-view cone angle (eq. 16); None uses the camera's HFOV as the paper", "rad"),
    )
    wall_distance_m: float = field(default=0.1, metadata=_why("d: plant wall offset (eq. 18)", "m"))
    band_distance_m: float = field(default=1.0, metadata=_why("l_dist (eq. 20)", "m"))
    band_tolerance_m: float = field(default=0.1, metadata=_why("epsilon (eq. 20)", "m"))
    step_m: float = field(default=0.2, metadata=_why("r_d: step limit, always on (eq. 21)", "m"))

    def __post_init__(self) -> None:
        object.__setattr__(
            self,
            "workspace_centre_m",
            _vector3("constraints", "workspace_centre_m", self.workspace_centre_m),
        )
        _positive("constraints", "workspace_radius_m", self.workspace_radius_m)
        if self.cone_fov_rad is not None:
            _open_interval(
                "constraints",
                "cone_fov_rad",
                self.cone_fov_rad,
                0.0,
                math.pi,
                "a number in (0, pi) or none",
            )
        _non_negative("constraints", "wall_distance_m", self.wall_distance_m)
        _positive("constraints", "band_distance_m", self.band_distance_m)
        _positive("constraints", "band_tolerance_m", self.band_tolerance_m)
        if self.band_tolerance_m >= self.band_distance_m:
            raise ConfigError(
                "constraints.band_tolerance_m", self.band_tolerance_m, "a number < band_distance_m"
            )
        _positive("constraints", "step_m", self.step_m)


@dataclass(frozen=True, kw_only=True)
class PlannerConfig:
    """Which planner chooses the next viewpoint, and how the BVE optimises."""

    kind: PlannerKind = field(default="bve", metadata=_why("bve, or a baseline: random, circle"))
    optimiser: OptimiserName = field(
        default="slsqp",
        metadata=_why("SLSQP: same viewpoints as trust-constr (interior point) at ~1/30 of the time"),
    )
    planning_model: PlanningModel = field(
        default="paper",
        metadata=_why("paper: Σn = R Σc R^T whatever is measured; consistent: the filter's information"),
    )
    approach_aggressiveness: float = field(
        default=0.0,
        metadata=_why("a in eq. 13; 0 turns the approach term off (E1-E10 do not use it)"),
    )
    approach_set_point: float = field(default=10.0, metadata=_why("b in eq. 13: iteration of act = 1/2"))
    prior_source: PriorSource = field(
        default="auto",
        metadata=_why(
            "Sigma_o: filter = the EKF's P; views = P0 fused with Sigma_n of every view (eq. 9, "
            "reproduces the paper's circling); auto = views for paper, filter for consistent"
        ),
    )
    max_eigenvalue_trace_weight: float = field(
        default=0.5,
        metadata=_why(
            "tau: trace tie-break added to eq. 11 where its top eigenvalue is flat (0 = as printed)"
        ),
    )
    starts: int = field(
        default=2,
        metadata=_why("local optimisations per plan, from the best-scoring of 15 seed points"),
    )
    joint_margin_weight: float = field(
        default=1.0,
        metadata=_why(
            "with the arm: weight of a soft barrier keeping each joint a tenth of its range off its "
            "limits (0 = none: the arm then folds against its limits and approaches stall)"
        ),
    )
    failed_view_width_deg: float = field(
        default=25.0,
        metadata=_why(
            "theta0: the BVE discounts views within about this angle of a view that measured "
            "nothing (seen from the estimate): the target is hidden from there (0 = off, the paper)",
            "deg",
        ),
    )
    horizon: int = field(
        default=1,
        metadata=_why(
            "views planned ahead (receding horizon: the best H views together, the first executed); "
            "1 = the paper's greedy BVE. With the arm, views 2..H are planned without its kinematics "
            "and the first is solved in joint space counting them as fused"
        ),
    )
    max_iterations: int = field(default=100, metadata=_why("optimiser iteration cap"))
    feasibility_tol: float = field(
        default=1e-7, metadata=_why("largest constraint value accepted as feasible", "m or m^2")
    )

    def __post_init__(self) -> None:
        _choice("planner", "kind", self.kind, PlannerKind)
        _choice("planner", "optimiser", self.optimiser, OptimiserName)
        _choice("planner", "planning_model", self.planning_model, PlanningModel)
        _choice("planner", "prior_source", self.prior_source, PriorSource)
        _non_negative("planner", "approach_aggressiveness", self.approach_aggressiveness)
        _non_negative("planner", "approach_set_point", self.approach_set_point)
        _non_negative("planner", "max_eigenvalue_trace_weight", self.max_eigenvalue_trace_weight)
        _non_negative("planner", "joint_margin_weight", self.joint_margin_weight)
        _positive_int("planner", "starts", self.starts, 1000)
        if not 0.0 <= _number("planner", "failed_view_width_deg", self.failed_view_width_deg) <= 90.0:
            raise ConfigError(
                "planner.failed_view_width_deg", self.failed_view_width_deg, "a number in [0, 90]"
            )
        _positive_int("planner", "max_iterations", self.max_iterations, 100_000)
        _positive_int("planner", "horizon", self.horizon)
        if self.horizon > 6:
            raise ConfigError("planner.horizon", self.horizon, "an integer in [1, 6]")
        _positive("planner", "feasibility_tol", self.feasibility_tol)


@dataclass(frozen=True, kw_only=True)
class ProtocolConfig:
    """The paper's Monte-Carlo protocol for the synthetic world."""

    fruit_half_extent_m: float = field(default=1.0, metadata=_why("fruit k ~ U[-1, 1]^3 m", "m"))
    camera_half_extent_m: float = field(default=2.0, metadata=_why("camera start ~ U[-2, 2]^3 m", "m"))
    initial_error_m: float = field(
        default=0.15, metadata=_why("initial estimate = k + U[-0.15, 0.15]^3 m", "m")
    )
    steps: int = field(
        default=30,
        metadata=_why(
            "views per run after the first: ~15 to reach the feasible set at 0.2 m a step, ~15 to refine"
        ),
    )

    def __post_init__(self) -> None:
        _positive("protocol", "fruit_half_extent_m", self.fruit_half_extent_m)
        _positive("protocol", "camera_half_extent_m", self.camera_half_extent_m)
        _non_negative("protocol", "initial_error_m", self.initial_error_m)
        _positive_int("protocol", "steps", self.steps, 10_000)


@dataclass(frozen=True, kw_only=True)
class RobotConfig:
    """The arm for experiments with kinematic feasibility (E5, E10) and for episodes."""

    name: RobotName = field(default="manipulator_h", metadata=_why("the paper's arm"))
    joint_limits: str = field(
        default="auto",
        metadata=_why(
            "Manipulator-H: emanual = ROBOTIS operating ranges (J1 +-pi, J3 -pi/2..3pi/4, ...); "
            "urdf = the URDF's conservative +-pi/2. Other arms: urdf. auto: emanual for "
            "manipulator_h, urdf for the others"
        ),
    )
    formulation: Formulation = field(
        default="joint",
        metadata=_why(
            "kinematic feasibility: joint = optimise q (faster, succeeds more); cartesian = IK constraint"
        ),
    )

    def __post_init__(self) -> None:
        _choice("robot", "name", self.name, RobotName)
        _choice("robot", "formulation", self.formulation, Formulation)
        if self.joint_limits not in ("auto", "urdf", "emanual") or (
            self.joint_limits == "emanual" and self.name != "manipulator_h"
        ):
            raise ConfigError(
                "robot.joint_limits", self.joint_limits, "auto, urdf, or emanual for manipulator_h"
            )

    @property
    def limit_set(self) -> str:
        """The joint limits in force: ``joint_limits`` with ``auto`` resolved for this arm."""
        if self.joint_limits == "auto":
            return "emanual" if self.name == "manipulator_h" else "urdf"
        return self.joint_limits


def _range(
    section: str, name: str, value: Any, lo: float = -math.inf, hi: float = math.inf
) -> tuple[float, float]:
    try:
        a, b = (float(x) for x in value)
    except (TypeError, ValueError):
        raise ConfigError(f"{section}.{name}", value, "a pair (low, high)") from None
    if not (math.isfinite(a) and math.isfinite(b) and lo <= a <= b <= hi):
        bounds = f"low >= {lo:g}" + (f", high <= {hi:g}" if math.isfinite(hi) else "")
        raise ConfigError(f"{section}.{name}", value, f"a pair low <= high, {bounds}")
    return (a, b)


FruitType = Literal["cherry", "cocktail", "round", "beefsteak", "plum"]
TrussLayout = Literal["chain", "cluster"]
RipenessName = Literal["green", "breaker", "turning", "pink", "light_red", "red"]
OtherTrussesRipeness = Literal["unripe", "mixed"]

FRUIT_TYPE_DIAMETER_M: dict[str, tuple[float, float]] = {
    "cherry": (0.015, 0.030),
    "cocktail": (0.030, 0.045),
    "round": (0.047, 0.067),
    "beefsteak": (0.067, 0.100),
    "plum": (0.035, 0.050),
}
"""Equatorial (horizontal) diameter range of each fruit type [m] (docs/greenhouse.md)."""

FRUIT_TYPE_SHAPE_INDEX: dict[str, tuple[float, float]] = {
    "cherry": (0.90, 1.00),
    "cocktail": (0.85, 1.00),
    "round": (0.80, 0.95),
    "beefsteak": (0.60, 0.80),
    "plum": (1.20, 1.60),
}
"""Shape index (height / width) range of each fruit type (docs/greenhouse.md)."""


def _int_at_least(section: str, name: str, value: Any, low: int) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not low <= value <= MAX_COUNT:
        raise ConfigError(f"{section}.{name}", value, f"an integer in [{low}, {MAX_COUNT}]")


def _optional_range(
    section: str, name: str, value: Any, lo: float = -math.inf, hi: float = math.inf
) -> tuple[float, float] | None:
    return None if value is None else _range(section, name, value, lo, hi)


@dataclass(frozen=True, kw_only=True)
class SceneConfig:
    """The greenhouse scene: the arm on a pedestal before a high-wire tomato row (robot base
    frame). Plants, trusses, fruit, leaves and light are drawn from the scene's seed within
    these settings; ``bve_mj.sim.scene`` documents the model."""

    pedestal_height_m: float = field(
        default=0.75,
        metadata=_why("robot base above the floor: puts trusses at 0.0-0.45 m within reach", "m"),
    )
    row_x_m: float = field(default=0.50, metadata=_why("stem line of the plant row in front of the arm", "m"))
    plants: int = field(default=5, metadata=_why("stems along the row, 0.3-0.5 m apart"))
    target_x_m: tuple[float, float] = field(
        default=(0.40, 0.45), metadata=_why("ripe target centre x: on the robot side of the row", "m")
    )
    target_y_m: tuple[float, float] = field(default=(-0.20, 0.20), metadata=_why("target centre y", "m"))
    target_z_m: tuple[float, float] = field(default=(0.05, 0.40), metadata=_why("target centre z", "m"))
    fruit_type: FruitType = field(
        default="round",
        metadata=_why(
            "cherry, cocktail, round, beefsteak or plum: sets the default size and shape-index "
            "ranges (docs/greenhouse.md)"
        ),
    )
    fruit_radius_m: tuple[float, float] | None = field(
        default=None,
        metadata=_why(
            "equatorial radius range of the fruit, each drawn within it; None = from fruit_type "
            "(round: 23.5-33.5 mm)",
            "m",
        ),
    )
    shape_index: tuple[float, float] | None = field(
        default=None,
        metadata=_why(
            "height / width range, each fruit drawn within it (< 1 flattened, > 1 elongated); "
            "None = from fruit_type (round: 0.80-0.95)"
        ),
    )
    trusses: int = field(
        default=3,
        metadata=_why("trusses near the target, one of them the target's, on the plants around it"),
    )
    fruit_per_truss: int = field(
        default=5, metadata=_why("fruit on each truss (round 4-8, cocktail 8-14, cherry 12-25)")
    )
    target_index: int = field(
        default=0,
        metadata=_why("which fruit of its truss is the target, 0 = the one nearest the stem (ripens first)"),
    )
    truss_layout: TrussLayout = field(
        default="chain",
        metadata=_why(
            "chain: fruit one after another along the bending rachis, touching; cluster: fruit "
            "alternating on both sides of it (two rows), touching"
        ),
    )
    ripeness: tuple[RipenessName, ...] = field(
        default=(),
        metadata=_why(
            "ripeness class of each fruit of the target's truss, index 0 nearest the stem "
            "(green, breaker, turning, pink, light_red, red); empty = drawn, ripening from the "
            "stem outward: fruit inward of the target 0-1 classes riper each, the one just outward "
            "3-4 classes less ripe (the target is its truss's ripe one), each further one 0-1 less"
        ),
    )
    target_ripeness: RipenessName = field(
        default="red", metadata=_why("the target's class when ripeness is drawn (ignored when it is given)")
    )
    other_trusses_ripeness: OtherTrussesRipeness = field(
        default="unripe",
        metadata=_why(
            "the other trusses, ripening from the stem outward: unripe = first fruit green, "
            "breaker or turning (no red beside the target); mixed = first fruit of any class"
        ),
    )
    leaf_density: float = field(
        default=1.0,
        metadata=_why(
            "scales the number of compound leaves (1 = one every 5-8 cm of stem above the "
            "stripped ripe zone; 0 = none)"
        ),
    )
    leaves_per_plant: int | None = field(
        default=None,
        metadata=_why(
            "legacy (leaflets per stem in the old scene): when set, scales leaf_density by it / 16"
        ),
    )
    distractors: int | None = field(
        default=None,
        metadata=_why(
            "legacy: when set, this many fruit in all on max(1, trusses - 1) other trusses (0 = only "
            "the target's truss); None = trusses - 1 other trusses of fruit_per_truss fruit each"
        ),
    )
    sun_azimuth_deg: tuple[float, float] = field(
        default=(135.0, 225.0),
        metadata=_why(
            "where the sun is, drawn in this range: 0 = behind the row (+x, backlit fruit), "
            "180 = behind the robot (front lit), 90 = +y",
            "deg",
        ),
    )
    sun_elevation_deg: tuple[float, float] = field(
        default=(40.0, 70.0), metadata=_why("sun above the horizon, drawn in this range", "deg")
    )
    sun_intensity: tuple[float, float] = field(
        default=(0.45, 0.75),
        metadata=_why("diffuse intensity of the sun (direct light), drawn in this range"),
    )
    light_intensity: tuple[float, float] | None = field(
        default=None, metadata=_why("legacy name of sun_intensity: when set, it replaces it")
    )
    sky_intensity: float = field(
        default=0.6,
        metadata=_why("diffuse sky through the glass: uniform ambient plus soft light from above"),
    )
    backlight: float = field(
        default=0.0,
        metadata=_why("intensity of a low light from behind the row towards the camera; 0 = none"),
    )
    shadows: bool = field(
        default=False, metadata=_why("the sun casts hard shadows: several times the render cost on a CPU")
    )
    headlight: bool = field(
        default=False, metadata=_why("a light on the camera (MuJoCo's headlight), like a flash or ring light")
    )

    def __post_init__(self) -> None:
        _positive("scene", "pedestal_height_m", self.pedestal_height_m)
        _positive("scene", "row_x_m", self.row_x_m)
        _positive_int("scene", "plants", self.plants, 50)
        _positive_int("scene", "trusses", self.trusses, 20)
        _positive_int("scene", "fruit_per_truss", self.fruit_per_truss, 40)
        _int_at_least("scene", "target_index", self.target_index, 0)
        if self.target_index >= self.fruit_per_truss:
            raise ConfigError(
                "scene.target_index",
                self.target_index,
                f"an integer < fruit_per_truss = {self.fruit_per_truss}",
            )
        for name in ("leaves_per_plant", "distractors"):
            v = getattr(self, name)
            if v is not None:
                _int_at_least("scene", name, v, 0)
        for name in ("target_x_m", "target_y_m", "target_z_m"):
            object.__setattr__(self, name, _range("scene", name, getattr(self, name)))
        _choice("scene", "fruit_type", self.fruit_type, FruitType)
        _choice("scene", "truss_layout", self.truss_layout, TrussLayout)
        _choice("scene", "target_ripeness", self.target_ripeness, RipenessName)
        _choice("scene", "other_trusses_ripeness", self.other_trusses_ripeness, OtherTrussesRipeness)
        object.__setattr__(
            self,
            "fruit_radius_m",
            _optional_range("scene", "fruit_radius_m", self.fruit_radius_m, 1e-3, 0.15),
        )
        shape = _optional_range("scene", "shape_index", self.shape_index, 0.0, 5.0)
        if shape is not None and shape[0] <= 0.0:
            raise ConfigError("scene.shape_index", self.shape_index, "a pair 0 < low <= high <= 5")
        object.__setattr__(self, "shape_index", shape)
        classes = get_args(RipenessName)
        given = self.ripeness
        if isinstance(given, (str, bytes, Mapping)) or not isinstance(given, (list, tuple)):
            raise ConfigError(
                "scene.ripeness", given, "a list of ripeness classes (" + ", ".join(classes) + ")"
            )
        for name in given:
            if name not in classes:
                raise ConfigError("scene.ripeness", list(given), "ripeness classes: " + ", ".join(classes))
        if given and len(given) != self.fruit_per_truss:
            raise ConfigError(
                "scene.ripeness", list(given), f"{self.fruit_per_truss} classes (fruit_per_truss), or none"
            )
        object.__setattr__(self, "ripeness", tuple(given))
        _non_negative("scene", "leaf_density", self.leaf_density)
        object.__setattr__(
            self, "sun_azimuth_deg", _range("scene", "sun_azimuth_deg", self.sun_azimuth_deg, -360.0, 360.0)
        )
        object.__setattr__(
            self, "sun_elevation_deg", _range("scene", "sun_elevation_deg", self.sun_elevation_deg, 0.0, 90.0)
        )
        object.__setattr__(self, "sun_intensity", _range("scene", "sun_intensity", self.sun_intensity, 0.0))
        object.__setattr__(
            self, "light_intensity", _optional_range("scene", "light_intensity", self.light_intensity, 0.0)
        )
        _non_negative("scene", "sky_intensity", self.sky_intensity)
        _non_negative("scene", "backlight", self.backlight)
        for name in ("shadows", "headlight"):
            if not isinstance(getattr(self, name), bool):
                raise ConfigError(f"scene.{name}", getattr(self, name), "true or false")
        if self.target_x_m[1] >= self.row_x_m:
            raise ConfigError("scene.target_x_m", self.target_x_m, f"values below row_x_m = {self.row_x_m}")

    @property
    def radius_range_m(self) -> tuple[float, float]:
        """Equatorial fruit radius range [m]: ``fruit_radius_m``, else half ``fruit_type``'s diameters."""
        if self.fruit_radius_m is not None:
            return self.fruit_radius_m
        lo, hi = FRUIT_TYPE_DIAMETER_M[self.fruit_type]
        return (lo / 2.0, hi / 2.0)

    @property
    def shape_index_range(self) -> tuple[float, float]:
        """Height / width range: ``shape_index``, else ``fruit_type``'s."""
        return self.shape_index if self.shape_index is not None else FRUIT_TYPE_SHAPE_INDEX[self.fruit_type]

    @property
    def sun_intensity_range(self) -> tuple[float, float]:
        """The sun's intensity range: ``light_intensity`` (legacy) when set, else ``sun_intensity``."""
        return self.light_intensity if self.light_intensity is not None else self.sun_intensity

    @property
    def leaf_scale(self) -> float:
        """``leaf_density``, times ``leaves_per_plant / 16`` when the legacy setting is given."""
        legacy = 1.0 if self.leaves_per_plant is None else self.leaves_per_plant / 16.0
        return self.leaf_density * legacy


@dataclass(frozen=True, kw_only=True)
class SensorConfig:
    """Sensor realism, seeded: off (ideal) by default, on in the ``realistic`` preset."""

    image_noise_std: float = field(default=0.0, metadata=_why("Gaussian pixel noise, 8-bit levels"))
    focal_error_rel: float = field(
        default=0.0, metadata=_why("std of the relative error of the focal length the detector assumes")
    )
    principal_point_error_px: float = field(
        default=0.0, metadata=_why("std of the principal-point error the detector assumes", "px")
    )
    encoder_noise_rad: float = field(default=0.0, metadata=_why("joint encoder noise std", "rad"))

    def __post_init__(self) -> None:
        for f in ("image_noise_std", "focal_error_rel", "principal_point_error_px", "encoder_noise_rad"):
            _non_negative("sensor", f, getattr(self, f))

    @classmethod
    def realistic(cls) -> SensorConfig:
        """OAK-1-like: 2 levels of noise, 1% focal and 2 px principal-point calibration error,
        Dynamixel Pro encoder resolution (~0.0004 rad at 501,923 counts/turn) as noise."""
        return cls(
            image_noise_std=2.0, focal_error_rel=0.01, principal_point_error_px=2.0, encoder_noise_rad=4e-4
        )


@dataclass(frozen=True, kw_only=True)
class DetectorConfig:
    """Colour segmentation, separation of touching fruit (outline arcs grouped into circles),
    and circle (cone) fit of the target tomato, with the checks that refuse a poor one."""

    red_hue_max: int = field(default=8, metadata=_why("ripe red: OpenCV hue <= this or >= red_hue_min_wrap"))
    red_hue_min_wrap: int = field(default=170, metadata=_why("ripe red wraps around hue 180"))
    min_saturation: int = field(default=110, metadata=_why("excludes pinkish highlights and grey", "0-255"))
    min_value: int = field(default=40, metadata=_why("excludes deep shadow", "0-255"))
    min_area_px: int = field(default=25, metadata=_why("smaller blobs are noise", "px"))
    min_boundary_points: int = field(default=12, metadata=_why("fewest silhouette points for a fit"))
    outlier_px: float = field(
        default=1.5,
        metadata=_why("boundary points this far inside the fitted circle are occluder edges", "px"),
    )
    extend_hue_max: int = field(
        default=25,
        metadata=_why(
            "skin up to this hue (orange-yellow: a highlight, a blush, uneven colour) counts as ripe "
            "where it touches ripe pixels, so a red fruit's silhouette is whole; <= the ripe hue "
            "limit turns it off (stems and leaves start at 38)",
            "0-180",
        ),
    )
    ripe_class: str | None = field(
        default=None,
        metadata=_why(
            "the least ripe class that counts as ripe (red, light_red, pink, turning; orange = turning): "
            "its hue limit (ripe_hue_limits) replaces red_hue_max; None: red_hue_max decides"
        ),
    )
    corner_px: float = field(
        default=1.5,
        metadata=_why(
            "concave corners of a ripe blob's outline deeper than this cut it into arcs (where two "
            "touching fruit meet, a calyx notch, a leaf tip)",
            "px",
        ),
    )
    junction_margin: int = field(
        default=4,
        metadata=_why("outline points left out at each end of an arc at a corner (blended with a neighbour)"),
    )
    arc_tol_px: float = field(
        default=2.0,
        metadata=_why(
            "an arc belongs to a fruit's circle when half its points or more lie within this of it "
            "(or 4% of the radius) and almost none further outside",
            "px",
        ),
    )
    min_arc_deg: float = field(
        default=150.0,
        metadata=_why("fewest degrees of the target's outline seen (after trimming) to measure it", "deg"),
    )
    max_fit_rms_px: float = field(
        default=0.8, metadata=_why("largest rms residual of the silhouette points kept in the fit", "px")
    )
    max_fit_sigma_px: float = field(
        default=0.5,
        metadata=_why(
            "largest 1-sigma centre uncertainty of the fit itself (short or ragged arcs), half the "
            "centre error a measurement claims; a looser fit is refused rather than reported",
            "px",
        ),
    )
    max_outside_share: float = field(
        default=0.05,
        metadata=_why(
            "largest share of the target's outline points more than outlier_px outside its fitted "
            "circle (more: the outline is not one fruit, a merged blob)"
        ),
    )
    min_radius_px: float = field(
        default=6.0,
        metadata=_why(
            "smallest apparent radius of a fruit (a 15 mm cherry at 1.2 m); smaller circles are specks "
            "of colour",
            "px",
        ),
    )
    size_tolerance_rel: float = field(
        default=0.5,
        metadata=_why(
            "when the caller passes the expected apparent radius, a fitted radius off by more than this "
            "share (either way) is not the target (a fragment, a merged blob, another fruit)"
        ),
    )

    ambiguity_ratio: float = field(
        default=20.0,
        metadata=_why(
            "when the estimate allows two fruit and the likelier is less than this many times as "
            "likely (3-D Mahalanobis distance of each to the estimate), the view is ambiguous and "
            "measures nothing"
        ),
    )

    @staticmethod
    def ripe_hue_limits() -> dict[str, int]:
        """The OpenCV hue (0-180) up to which the coloured skin of each ripeness class reaches,
        measured on the scene's rendered skins (``bve_mj.sim.textures``) in white light: red and
        the red of light red 1-8, the yellow-orange of light red and pink up to 30-34, turning
        (and the legacy orange) 33-37; breaker and green 38-45 with the stems, leaves 45-60,
        never ripe. ``ripe_class`` picks one."""
        return {"red": 8, "light_red": 30, "pink": 34, "turning": 37, "orange": 37}

    def __post_init__(self) -> None:
        for name in ("red_hue_max", "red_hue_min_wrap", "min_saturation", "min_value", "extend_hue_max"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or not 0 <= v <= 255:
                raise ConfigError(f"detector.{name}", v, "an integer in [0, 255]")
        _positive_int("detector", "min_area_px", self.min_area_px)
        _positive_int("detector", "min_boundary_points", self.min_boundary_points)
        _positive("detector", "outlier_px", self.outlier_px)
        limits = self.ripe_hue_limits()
        known = isinstance(self.ripe_class, str) and self.ripe_class in limits
        if self.ripe_class is not None and not known:
            raise ConfigError("detector.ripe_class", self.ripe_class, "one of " + ", ".join(limits))
        _open_interval("detector", "max_outside_share", self.max_outside_share, 0.0, 1.0, "a share in (0, 1)")
        _positive("detector", "corner_px", self.corner_px)
        _positive_int("detector", "junction_margin", self.junction_margin)
        _positive("detector", "arc_tol_px", self.arc_tol_px)
        _open_interval("detector", "min_arc_deg", self.min_arc_deg, 0.0, 360.0, "a number in (0, 360)")
        _positive("detector", "max_fit_rms_px", self.max_fit_rms_px)
        _positive("detector", "max_fit_sigma_px", self.max_fit_sigma_px)
        _non_negative("detector", "min_radius_px", self.min_radius_px)
        _positive("detector", "size_tolerance_rel", self.size_tolerance_rel)
        if isinstance(self.ambiguity_ratio, bool) or not (
            isinstance(self.ambiguity_ratio, (int, float)) and 1.0 < self.ambiguity_ratio < math.inf
        ):
            raise ConfigError("detector.ambiguity_ratio", self.ambiguity_ratio, "a finite number > 1")

    @property
    def ripe_hue_max(self) -> int:
        """The hue limit of ripe pixels: that of ``ripe_class``, else ``red_hue_max``."""
        return self.red_hue_max if self.ripe_class is None else self.ripe_hue_limits()[self.ripe_class]


@dataclass(frozen=True, kw_only=True)
class FaultConfig:
    """Injected faults (all off by default), drawn per view from the episode's fault stream.

    For robustness studies: the fault-injection suite runs hundreds of seeded episodes with
    these on and checks that every one ends cleanly, within limits and with a bounded error.
    """

    drop_p: float = field(default=0.0, metadata=_why("a view's detection is lost (fruit hidden)"))
    hidden_views: tuple[int, ...] = field(
        default=(), metadata=_why("views whose detection is always lost (0 = the start view)")
    )
    false_p: float = field(
        default=0.0,
        metadata=_why("a view measures another red object 5-30 cm from the fruit (second blob, red leaf)"),
    )
    outlier_p: float = field(
        default=0.0, metadata=_why("a view's measurement gets a gross error (10-50 sigma)")
    )
    ik_failure_p: float = field(default=0.0, metadata=_why("a move's IK fails: the arm must hold"))
    planner_failure_p: float = field(
        default=0.0, metadata=_why("a plan's optimiser fails (raises): the episode must fall back")
    )

    def __post_init__(self) -> None:
        for name in ("drop_p", "false_p", "outlier_p", "ik_failure_p", "planner_failure_p"):
            v = _number("faults", name, getattr(self, name))
            if not 0.0 <= v <= 1.0:
                raise ConfigError(f"faults.{name}", getattr(self, name), "a probability in [0, 1]")
        views = self.hidden_views
        if isinstance(views, (str, bytes)) or not isinstance(views, (tuple, list)):
            raise ConfigError("faults.hidden_views", views, "a list of view numbers >= 0")
        for v in views:
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
                raise ConfigError("faults.hidden_views", views, "a list of view numbers >= 0")
        object.__setattr__(self, "hidden_views", tuple(int(v) for v in views))
        if self.false_p + self.outlier_p > 1.0:
            raise ConfigError("faults.false_p", self.false_p, "false_p + outlier_p <= 1")

    @property
    def any(self) -> bool:
        return bool(
            self.drop_p or self.hidden_views or self.false_p or self.outlier_p
            or self.ik_failure_p or self.planner_failure_p
        )  # fmt: skip


@dataclass(frozen=True, kw_only=True)
class EpisodeConfig:
    """A closed-loop MuJoCo episode: constraints adapted to the arm, stopping rules, approach."""

    experiment: str = field(default="E5", metadata=_why("constraint set and loss (E5: all of the paper's)"))
    views: int = field(default=15, metadata=_why("most planned views after the first"))
    band_distance_m: float = field(
        default=0.30,
        metadata=_why("distance band centre adapted to the arm: 0.645 m reach, fruit at ~0.45 m", "m"),
    )
    band_tolerance_m: float = field(default=0.08, metadata=_why("distance band half-width", "m"))
    step_m: float = field(default=0.10, metadata=_why("step limit: ~20 deg of view change at 0.3 m", "m"))
    prior: str = field(
        default="detection",
        metadata=_why(
            "how the prior is made. detection: the target picked in a first image from the ready pose "
            "(which looks at a coarse guess, fruit + U[-e, e]^3): the prior mean lies on the ray to "
            "the fruit, its range off by U[-e, e] and its bearing by U[-l, l] each way "
            "(l = initial_lateral_error_m), the covariance elongated to match. cube: the paper's "
            "protocol, mean = fruit + U[-e, e]^3, isotropic; in a truss of touching fruit 5 cm apart "
            "it does not say which fruit is meant (episodes end ambiguous)"
        ),
    )
    initial_error_m: float = field(
        default=0.05,
        metadata=_why("e: the prior's range error (detection) or error per axis (cube)", "m"),
    )
    initial_lateral_error_m: float | None = field(
        default=None,
        metadata=_why(
            "l: the detection prior's error across the ray, each way (a first detection's bearing). "
            "Unset: a third of the fruit type's mean radius (the first detection's ray passes "
            "through the fruit it picked, near its centre; a bearing error as wide as a cherry "
            "would not say which cherry is meant)",
            "m",
        ),
    )
    stop_sigma_m: float = field(
        default=0.0015, metadata=_why("stop when the largest posterior std falls below this", "m")
    )
    converge_after: int = field(
        default=3,
        metadata=_why(
            "converged needs at least this many accepted measurements since the last belief reset: two "
            "views triangulate a fruit, but a neighbour measured in one of them is then still "
            "consistent with the other (seen in truss_cluster: 18 mm off, claiming 1.4 mm); a third "
            "from elsewhere tells"
        ),
    )
    stop_stable_m: float = field(
        default=0.0003, metadata=_why("stop when the estimate moves less than this ...", "m")
    )
    stable_views: int = field(default=3, metadata=_why("... over this many views"))
    stall_m: float = field(
        default=0.005,
        metadata=_why(
            "stop when the camera moved less than this over stable_views views: the planner finds "
            "no better reachable view, and repeating one view fuses the same bias again "
            "(outcome stalled, or approach_blocked in approach mode)",
            "m",
        ),
    )
    gate_probability: float = field(
        default=0.99999,
        metadata=_why(
            "NIS gate in the closed loop unless filter.gate_probability is set: rejects false "
            "detections (NIS in the thousands) but not the true ones a wrong fruit-radius guess "
            "biases in range (NIS up to ~20 seen at 0.999)"
        ),
    )
    approach: bool = field(default=False, metadata=_why("approach mode: eq. 13 term on, no band"))
    approach_distance_m: float = field(
        default=0.10, metadata=_why("approach ends with the camera this close to the estimate", "m")
    )
    approach_wall_distance_m: float = field(
        default=0.04,
        metadata=_why(
            "approach mode's plant wall, in front of the fruit centre: the paper's 0.1 m would keep "
            "the camera at >= 0.1 m; the row itself stands behind the fruit",
            "m",
        ),
    )

    def __post_init__(self) -> None:
        _positive_int("episode", "views", self.views, 10_000)
        _positive_int("episode", "stable_views", self.stable_views, 100)
        _positive_int("episode", "converge_after", self.converge_after, 100)
        for f in ("band_distance_m", "band_tolerance_m", "step_m", "stop_sigma_m", "approach_distance_m"):
            _positive("episode", f, getattr(self, f))
        _non_negative("episode", "initial_error_m", self.initial_error_m)
        if self.initial_lateral_error_m is not None:
            _non_negative("episode", "initial_lateral_error_m", self.initial_lateral_error_m)
        if self.prior not in ("detection", "cube"):
            raise ConfigError("episode.prior", self.prior, "detection or cube")
        _non_negative("episode", "stop_stable_m", self.stop_stable_m)
        _non_negative("episode", "stall_m", self.stall_m)
        _non_negative("episode", "approach_wall_distance_m", self.approach_wall_distance_m)
        if self.band_tolerance_m >= self.band_distance_m:
            raise ConfigError("episode.band_tolerance_m", self.band_tolerance_m, "a number < band_distance_m")
        if not isinstance(self.approach, bool):
            raise ConfigError("episode.approach", self.approach, "true or false")
        if not isinstance(self.experiment, str) or self.experiment.upper() not in {
            f"E{i}" for i in range(1, 11)
        }:
            raise ConfigError("episode.experiment", self.experiment, "one of E1..E10")
        _open_interval("episode", "gate_probability", self.gate_probability, 0.0, 1.0, "a number in (0, 1)")

    def lateral_error_m(self, fruit_radius_m: float) -> float:
        """l: ``initial_lateral_error_m``, or a third of ``fruit_radius_m`` when unset."""
        if self.initial_lateral_error_m is not None:
            return float(self.initial_lateral_error_m)
        return fruit_radius_m / 3.0


@dataclass(frozen=True, kw_only=True)
class Settings:
    """Every setting of a synthetic (paper-protocol) run."""

    camera: CameraConfig = field(default_factory=CameraConfig)
    fruit: FruitPrior = field(default_factory=FruitPrior)
    measurement: MeasurementConfig = field(default_factory=MeasurementConfig)
    filter: FilterConfig = field(default_factory=FilterConfig)
    constraints: ConstraintConfig = field(default_factory=ConstraintConfig)
    planner: PlannerConfig = field(default_factory=PlannerConfig)
    protocol: ProtocolConfig = field(default_factory=ProtocolConfig)
    robot: RobotConfig = field(default_factory=RobotConfig)
    scene: SceneConfig = field(default_factory=SceneConfig)
    sensor: SensorConfig = field(default_factory=SensorConfig)
    detector: DetectorConfig = field(default_factory=DetectorConfig)
    episode: EpisodeConfig = field(default_factory=EpisodeConfig)
    faults: FaultConfig = field(default_factory=FaultConfig)

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            expected = _SECTIONS[f.name]
            if not isinstance(value, expected):
                raise ConfigError(f.name, value, f"a {expected.__name__}")

    def sigma_c_m2(self) -> np.ndarray:
        """Σc, the camera-frame measurement covariance [m²] (x = depth, y/z lateral), (3, 3).

        Derived at the reference range ρ (1 m): lateral σ = ρ·σ_centre/f; range from the
        angular radius of a sphere, ρ = r / sin α, so σ_ρ/ρ combines the relative spread
        of the true radius (uniform ±s: s/√3) with the relative pixel error of the
        apparent radius (σ_r/r_px, r_px = f·tan α).
        """
        m = self.measurement
        if m.sigma_c_m2 is not None:
            return np.array(m.sigma_c_m2, dtype=float)
        rho = m.reference_range_m
        f = self.camera.focal_px
        sigma_lateral = rho * m.centre_sigma_px / f
        alpha = math.asin(min(self.fruit.radius_m / rho, 1.0))
        radius_px = f * math.tan(alpha)
        rel = math.hypot(self.fruit.size_spread_rel, m.radius_sigma_px / radius_px)
        sigma_range = rho * rel
        return np.diag([sigma_range**2, sigma_lateral**2, sigma_lateral**2])

    def for_world(self, world: WorldName) -> Settings:
        """These settings with the world-dependent defaults resolved. Every runner calls this
        first, so the Python API, the CLI and campaigns agree:

        - ``measurement.kind = "auto"`` becomes ``range`` in the synthetic world (the paper's
          EKF) and ``camera`` in MuJoCo;
        - ``filter.state = "auto"`` becomes ``centre`` in the synthetic world (the paper's
          state) and ``centre_radius`` in MuJoCo (the fruit's radius estimated with it);
        - in MuJoCo, a ``fruit`` section left at its defaults (the paper's r_k = 35 mm ±15%)
          becomes the prior of the scene's fruit type (:meth:`FruitPrior.for_scene`): the
          estimator knows the variety it is picking, not each fruit's size. Any value set in
          ``[fruit]`` keeps the whole section as given.
        """
        if world not in get_args(WorldName):
            raise ConfigError("world", world, "one of " + ", ".join(get_args(WorldName)))
        out = self
        if self.measurement.kind == "auto":
            kind: MeasurementKind = "range" if world == "synthetic" else "camera"
            out = dataclasses.replace(out, measurement=dataclasses.replace(out.measurement, kind=kind))
        if world == "synthetic" and self.filter.state == "centre_radius":
            raise ConfigError(
                "filter.state",
                self.filter.state,
                "auto or centre in the synthetic world (it measures the centre, not an image: "
                "centre_radius needs the MuJoCo world)",
            )
        if self.filter.state == "auto":
            state: StateKind = "centre" if world == "synthetic" else "centre_radius"
            out = dataclasses.replace(out, filter=dataclasses.replace(out.filter, state=state))
        if world == "mujoco" and self.fruit == FruitPrior():
            out = dataclasses.replace(out, fruit=FruitPrior.for_scene(self.scene))
        return out

    @property
    def estimates_calibration(self) -> bool:
        """Whether the state carries the camera's calibration biases: the radius is in the state
        and the sensor declares a calibration error (a per-episode bias, estimated)."""
        s = self.sensor
        return self.filter.state == "centre_radius" and (
            s.focal_error_rel > 0.0 or s.principal_point_error_px > 0.0
        )

    @property
    def prior_source(self) -> Literal["filter", "views"]:
        """The planner's Σo source with ``auto`` resolved."""
        src = self.planner.prior_source
        if src == "auto":
            return "views" if self.planner.planning_model == "paper" else "filter"
        return src

    @property
    def cone_fov_rad(self) -> float:
        c = self.constraints.cone_fov_rad
        return self.camera.hfov_rad if c is None else c


_SECTIONS: dict[str, type] = {
    "camera": CameraConfig,
    "fruit": FruitPrior,
    "measurement": MeasurementConfig,
    "filter": FilterConfig,
    "constraints": ConstraintConfig,
    "planner": PlannerConfig,
    "protocol": ProtocolConfig,
    "robot": RobotConfig,
    "scene": SceneConfig,
    "sensor": SensorConfig,
    "detector": DetectorConfig,
    "episode": EpisodeConfig,
    "faults": FaultConfig,
}


# --------------------------------------------------------------------------- loading
def _suggest(name: str, options: list[str]) -> str:
    close = difflib.get_close_matches(name, options, n=1)
    return f" (did you mean {close[0]!r}?)" if close else ""


def _section_from_dict(section: str, cls: type, data: Any) -> Any:
    if not isinstance(data, Mapping):
        raise ConfigError(section, data, "a table of settings")
    names = [f.name for f in dataclasses.fields(cls)]
    for key in data:
        if key not in names:
            raise ConfigError(
                f"{section}.{key}",
                data[key],
                "one of " + ", ".join(names) + _suggest(str(key), names),
            )
    return cls(**dict(data))


def settings_from_dict(data: Mapping[str, Any], base: Settings | None = None) -> Settings:
    """Build :class:`Settings` from nested mappings (as TOML gives), over ``base``'s values.

    Unknown sections or keys raise :class:`ConfigError` with a "did you mean" suggestion.
    """
    base = base or Settings()
    if not isinstance(data, Mapping):
        raise ConfigError("settings", data, "a table of sections")
    sections: dict[str, Any] = {}
    for key, value in data.items():
        if key not in _SECTIONS:
            names = list(_SECTIONS)
            raise ConfigError(str(key), value, "one of " + ", ".join(names) + _suggest(str(key), names))
        merged = (
            {**dataclasses.asdict(getattr(base, key)), **dict(value)} if isinstance(value, Mapping) else value
        )
        sections[key] = _section_from_dict(str(key), _SECTIONS[key], merged)
    return dataclasses.replace(base, **sections)


def load_settings(path: str | Path, base: Settings | None = None) -> Settings:
    """Read :class:`Settings` from a TOML file; missing keys keep ``base``'s values."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError("config", str(p), f"a readable TOML file ({exc.strerror})") from None
    except UnicodeDecodeError as exc:
        raise ConfigError(
            "config", str(p), f"a UTF-8 text TOML file (byte {exc.start} is not UTF-8)"
        ) from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError("config", str(p), f"valid TOML ({exc})") from None
    return settings_from_dict(data, base)


def settings_to_dict(settings: Settings) -> dict[str, Any]:
    """Plain nested dict of every setting plus the derived Σc (JSON-serialisable)."""
    out: dict[str, Any] = dataclasses.asdict(settings)
    out["derived"] = {
        "sigma_c_m2": settings.sigma_c_m2().tolist(),
        "focal_px": settings.camera.focal_px,
        "cone_fov_rad": settings.cone_fov_rad,
        "prior_source": settings.prior_source,
    }
    return out


def _walk(obj: Any, prefix: str) -> Iterator[tuple[str, Any, dataclasses.Field[Any]]]:
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        if dataclasses.is_dataclass(value):
            yield from _walk(value, f"{prefix}{f.name}.")
        else:
            yield f"{prefix}{f.name}", value, f


def describe(settings: Settings) -> list[str]:
    """One line per setting: name = value [unit]  # why. Then the derived Σc."""
    lines = []
    for name, value, f in _walk(settings, ""):
        unit = f.metadata.get("unit", "")
        shown = f"{value:.6g}" if isinstance(value, float) else repr(value)
        lines.append(f"{name} = {shown}{' [' + unit + ']' if unit else ''}  # {f.metadata.get('why', '')}")
    sc = np.sqrt(np.diag(settings.sigma_c_m2()))
    lines.append(
        f"derived Sigma_c std (depth, lateral, lateral) = "
        f"({sc[0] * 1e3:.1f}, {sc[1] * 1e3:.2f}, {sc[2] * 1e3:.2f}) mm at "
        f"{settings.measurement.reference_range_m:g} m; focal = {settings.camera.focal_px:.1f} px"
    )
    return lines
