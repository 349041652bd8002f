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
    "describe",
    "load_settings",
    "settings_from_dict",
    "settings_to_dict",
]

MeasurementKind = Literal["range", "camera"]
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
def _number(section: str, name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
        raise ConfigError(f"{section}.{name}", value, "a real number")
    v = float(value)
    if not math.isfinite(v):
        raise ConfigError(f"{section}.{name}", value, "a finite real number")
    return v


def _positive(section: str, name: str, value: Any) -> None:
    if _number(section, name, value) <= 0.0:
        raise ConfigError(f"{section}.{name}", value, "a number > 0")


def _non_negative(section: str, name: str, value: Any) -> None:
    if _number(section, name, value) < 0.0:
        raise ConfigError(f"{section}.{name}", value, "a number >= 0")


def _open_interval(section: str, name: str, value: Any, lo: float, hi: float, text: str) -> None:
    v = _number(section, name, value)
    if not lo < v < hi:
        raise ConfigError(f"{section}.{name}", value, text)


def _positive_int(section: str, name: str, value: Any) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise ConfigError(f"{section}.{name}", value, "an integer >= 1")


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

    def __post_init__(self) -> None:
        _open_interval("camera", "hfov_rad", self.hfov_rad, 0.0, math.pi, "a number in (0, pi)")
        _positive_int("camera", "width_px", self.width_px)
        _positive_int("camera", "height_px", self.height_px)

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

    def __post_init__(self) -> None:
        _positive("fruit", "radius_m", self.radius_m)
        _non_negative("fruit", "radius_spread_rel", self.radius_spread_rel)
        if self.radius_spread_rel >= 1.0:
            raise ConfigError("fruit.radius_spread_rel", self.radius_spread_rel, "a number in [0, 1)")


@dataclass(frozen=True, kw_only=True)
class MeasurementConfig:
    """What the filter measures, and the camera-frame covariance Σc it measures it with.

    Σc is derived from the camera, not invented (see :meth:`Settings.sigma_c_m2`): at the
    reference range ρ the lateral σ is ρ·σ_px/f, and the range σ combines the unknown
    true radius with the pixel error of the apparent radius. ``sigma_c_m2`` overrides the
    derivation with an explicit 3x3 (or diagonal) covariance in the camera frame.
    """

    kind: MeasurementKind = field(default="range", metadata=_why("the paper's EKF measures range only"))
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

    def __post_init__(self) -> None:
        _choice("measurement", "kind", self.kind, MeasurementKind)
        _positive("measurement", "centre_sigma_px", self.centre_sigma_px)
        _positive("measurement", "radius_sigma_px", self.radius_sigma_px)
        _positive("measurement", "reference_range_m", self.reference_range_m)
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
    """The EKF: static fruit (F = I), process noise Q, prior P0, optional NIS gating."""

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
        _non_negative("filter", "process_sigma_m", self.process_sigma_m)
        _positive("filter", "initial_sigma_m", self.initial_sigma_m)
        _positive_int("filter", "reset_after_rejections", self.reset_after_rejections)
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
        _positive_int("planner", "starts", self.starts)
        _positive_int("planner", "max_iterations", self.max_iterations)
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
        _positive_int("protocol", "steps", self.steps)


@dataclass(frozen=True, kw_only=True)
class RobotConfig:
    """The arm for experiments with kinematic feasibility (E5, E10) and for episodes."""

    name: RobotName = field(default="manipulator_h", metadata=_why("the paper's arm"))
    joint_limits: str = field(
        default="emanual",
        metadata=_why(
            "Manipulator-H: emanual = ROBOTIS operating ranges (J1 +-pi, J3 -pi/2..3pi/4, ...); "
            "urdf = the URDF's conservative +-pi/2. Other arms: urdf"
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
        if self.joint_limits not in ("urdf", "emanual") or (
            self.joint_limits == "emanual" and self.name != "manipulator_h"
        ):
            raise ConfigError("robot.joint_limits", self.joint_limits, "urdf, or emanual for manipulator_h")


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


@dataclass(frozen=True, kw_only=True)
class SceneConfig:
    """The greenhouse scene: the arm on a pedestal before a tomato row (robot base frame)."""

    pedestal_height_m: float = field(
        default=0.75,
        metadata=_why("robot base above the floor: puts trusses at 0.0-0.45 m within reach", "m"),
    )
    row_x_m: float = field(default=0.50, metadata=_why("stem line of the plant row in front of the arm", "m"))
    plants: int = field(default=5, metadata=_why("stems along the row, 0.4 m apart"))
    leaves_per_plant: int = field(default=16, metadata=_why("leaflets per stem"))
    target_x_m: tuple[float, float] = field(
        default=(0.40, 0.45), metadata=_why("ripe target centre x: on the robot side of the row", "m")
    )
    target_y_m: tuple[float, float] = field(default=(-0.20, 0.20), metadata=_why("target centre y", "m"))
    target_z_m: tuple[float, float] = field(default=(0.05, 0.40), metadata=_why("target centre z", "m"))
    fruit_radius_m: tuple[float, float] = field(
        default=(0.025, 0.045), metadata=_why("greenhouse tomato radii", "m")
    )
    distractors: int = field(default=4, metadata=_why("unripe green and orange fruit near the target"))
    light_intensity: tuple[float, float] = field(
        default=(0.55, 0.9), metadata=_why("diffuse intensity of the sun light, randomised")
    )
    shadows: bool = field(
        default=False, metadata=_why("the sun casts shadows: several times the render cost on a CPU")
    )

    def __post_init__(self) -> None:
        _positive("scene", "pedestal_height_m", self.pedestal_height_m)
        _positive("scene", "row_x_m", self.row_x_m)
        _positive_int("scene", "plants", self.plants)
        for name in ("leaves_per_plant", "distractors"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 0:
                raise ConfigError(f"scene.{name}", v, "an integer >= 0")
        for name in ("target_x_m", "target_y_m", "target_z_m"):
            object.__setattr__(self, name, _range("scene", name, getattr(self, name)))
        object.__setattr__(
            self, "fruit_radius_m", _range("scene", "fruit_radius_m", self.fruit_radius_m, 1e-3, 0.15)
        )
        object.__setattr__(
            self, "light_intensity", _range("scene", "light_intensity", self.light_intensity, 0.0)
        )
        if not isinstance(self.shadows, bool):
            raise ConfigError("scene.shadows", self.shadows, "true or false")
        if self.target_x_m[1] >= self.row_x_m:
            raise ConfigError("scene.target_x_m", self.target_x_m, f"values below row_x_m = {self.row_x_m}")


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
    """Colour segmentation and circle (cone) fit of the target tomato."""

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

    def __post_init__(self) -> None:
        for name in ("red_hue_max", "red_hue_min_wrap", "min_saturation", "min_value"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or not 0 <= v <= 255:
                raise ConfigError(f"detector.{name}", v, "an integer in [0, 255]")
        _positive_int("detector", "min_area_px", self.min_area_px)
        _positive_int("detector", "min_boundary_points", self.min_boundary_points)
        _positive("detector", "outlier_px", self.outlier_px)


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
    initial_error_m: float = field(
        default=0.05, metadata=_why("prior mean = fruit + U[-e, e]^3 (a coarse first detection)", "m")
    )
    stop_sigma_m: float = field(
        default=0.0015, metadata=_why("stop when the largest posterior std falls below this", "m")
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
        _positive_int("episode", "views", self.views)
        _positive_int("episode", "stable_views", self.stable_views)
        for f in ("band_distance_m", "band_tolerance_m", "step_m", "stop_sigma_m", "approach_distance_m"):
            _positive("episode", f, getattr(self, f))
        _non_negative("episode", "initial_error_m", self.initial_error_m)
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
        rel = math.hypot(self.fruit.radius_spread_rel / math.sqrt(3.0), m.radius_sigma_px / radius_px)
        sigma_range = rho * rel
        return np.diag([sigma_range**2, sigma_lateral**2, sigma_lateral**2])

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
