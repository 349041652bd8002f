"""Settings of the viewpoint constraints, the planner, the paper's synthetic protocol and the
robot."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import get_args

from bve_mj.config.fields import (
    Formulation,
    JointLimitSet,
    OptimiserName,
    PlannerKind,
    PlanningModel,
    PriorSource,
    RobotName,
    _choice,
    _non_negative,
    _number,
    _open_interval,
    _positive,
    _positive_int,
    _vector3,
    _why,
)
from bve_mj.errors import ConfigError

__all__ = ["ConstraintConfig", "PlannerConfig", "ProtocolConfig", "RobotConfig"]


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
    band_distance_m: float | None = field(
        default=None,
        metadata=_why(
            "l_dist (eq. 20). Unset: the world's preset (Settings.for_world): the paper's in the "
            "synthetic world; in MuJoCo adapted to the arm (0.645 m reach, fruit at ~0.45 m)",
            "m",
        ),
    )
    band_tolerance_m: float | None = field(
        default=None,
        metadata=_why("epsilon (eq. 20), the band's half-width. Unset: the world's preset", "m"),
    )
    step_m: float | None = field(
        default=None,
        metadata=_why(
            "r_d: step limit, always on (eq. 21). Unset: the world's preset: the paper's in the "
            "synthetic world; in MuJoCo ~20 deg of view change at the band distance",
            "m",
        ),
    )

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
        for name in ("band_distance_m", "band_tolerance_m", "step_m"):
            if getattr(self, name) is not None:
                _positive("constraints", name, getattr(self, name))
        if (
            self.band_tolerance_m is not None
            and self.band_distance_m is not None
            and self.band_tolerance_m >= self.band_distance_m
        ):
            raise ConfigError(
                "constraints.band_tolerance_m", self.band_tolerance_m, "a number < band_distance_m"
            )


@dataclass(frozen=True, kw_only=True)
class PlannerConfig:
    """Which planner chooses the next viewpoint, and how the BVE optimises."""

    kind: PlannerKind = field(
        default="bve",
        metadata=_why("bve, or a baseline: random, circle, fixed (three fixed collinear views)"),
    )
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
        metadata=_why(
            "local optimisations per plan, from the best-scoring of 15 seed points: the BVE without "
            "the arm, or with it under robot.formulation = cartesian; the joint formulation (the "
            "default with the arm) starts from the arm's configuration instead and ignores this"
        ),
    )
    joint_margin_weight: float = field(
        default=1.0,
        metadata=_why(
            "with the arm: weight of a soft barrier keeping each joint a tenth of its range off its "
            "limits (0 = none: the arm then folds against its limits and approaches stall)"
        ),
    )
    upright_weight: float | None = field(
        default=None,
        metadata=_why(
            "with the arm: weight of a soft preference for an upright eye-in-hand image "
            "(w(1 - cos roll) about the optical axis; the ready pose, each plan and each IK move "
            "then turn the roll upright as far as the look-at and a tenth of each joint's range "
            "allow). 0 = roll left free. Unset: the world's preset: 0 in the paper's protocol "
            "(its table unchanged), 0.1 in MuJoCo"
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
    untried_weight: float = field(
        default=1.0,
        metadata=_why(
            "beta: with failed views, the BVE's loss grows by beta per failed view near the "
            "candidate (the theta0 kernel; the dispersion loss's nats; with the max-eigenvalue loss "
            "the share 1 - e^-beta of the current largest variance), so the camera leaves a place "
            "where every view within a step failed instead of holding still (0 = off)",
            "nats",
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

    @property
    def upright(self) -> float:
        """``upright_weight`` as a number (unset reads as the paper's world: 0)."""
        return 0.0 if self.upright_weight is None else float(self.upright_weight)

    def __post_init__(self) -> None:
        _choice("planner", "kind", self.kind, PlannerKind)
        _choice("planner", "optimiser", self.optimiser, OptimiserName)
        _choice("planner", "planning_model", self.planning_model, PlanningModel)
        _choice("planner", "prior_source", self.prior_source, PriorSource)
        _non_negative("planner", "approach_aggressiveness", self.approach_aggressiveness)
        _non_negative("planner", "approach_set_point", self.approach_set_point)
        _non_negative("planner", "max_eigenvalue_trace_weight", self.max_eigenvalue_trace_weight)
        _non_negative("planner", "joint_margin_weight", self.joint_margin_weight)
        if self.upright_weight is not None:
            _non_negative("planner", "upright_weight", self.upright_weight)
        _positive_int("planner", "starts", self.starts, 1000)
        if not 0.0 <= _number("planner", "failed_view_width_deg", self.failed_view_width_deg) <= 90.0:
            raise ConfigError(
                "planner.failed_view_width_deg", self.failed_view_width_deg, "a number in [0, 90]"
            )
        if not 0.0 <= _number("planner", "untried_weight", self.untried_weight) <= 20.0:
            raise ConfigError("planner.untried_weight", self.untried_weight, "a number in [0, 20]")
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
    joint_limits: JointLimitSet = field(
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
        if self.joint_limits not in get_args(JointLimitSet) or (
            self.joint_limits == "emanual" and self.name != "manipulator_h"
        ):
            raise ConfigError(
                "robot.joint_limits",
                self.joint_limits,
                "one of " + ", ".join(get_args(JointLimitSet)) + " (emanual: manipulator_h only)",
            )

    @property
    def limit_set(self) -> str:
        """The joint limits in force: ``joint_limits`` with ``auto`` resolved for this arm."""
        if self.joint_limits == "auto":
            return "emanual" if self.name == "manipulator_h" else "urdf"
        return self.joint_limits
