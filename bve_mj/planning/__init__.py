"""Planning: losses, constraints, the BVE optimiser and baseline planners."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from bve_mj.config import LossName, Settings
from bve_mj.planning.baselines import CirclePlanner, FixedViewsPlanner, RandomPlanner
from bve_mj.planning.bve import BvePlanner
from bve_mj.planning.constraints import (
    Constraint,
    ConstraintName,
    DistanceBand,
    ExtraConstraints,
    FieldOfViewCone,
    OutsideFruit,
    PlantWall,
    StepLimit,
    WorkspaceSphere,
    build_constraints,
    max_violation,
)
from bve_mj.planning.information import (
    CameraInformation,
    FailedViewDiscount,
    ObservationInformation,
    RangeInformation,
    observation_information,
)
from bve_mj.planning.losses import (
    ApproachTerm,
    DispersionLoss,
    MaxEigenvalueLoss,
    Objective,
    UntriedTerm,
    approach_activation,
)
from bve_mj.planning.plan import LearnsFromFailedViews, LearnsFromFusedViews, Planner, PlanStatus, ViewPlan

__all__ = [
    "ApproachTerm",
    "BvePlanner",
    "CameraInformation",
    "CirclePlanner",
    "Constraint",
    "ConstraintName",
    "DispersionLoss",
    "DistanceBand",
    "ExtraConstraints",
    "FailedViewDiscount",
    "FieldOfViewCone",
    "FixedViewsPlanner",
    "LearnsFromFailedViews",
    "LearnsFromFusedViews",
    "MaxEigenvalueLoss",
    "Objective",
    "ObservationInformation",
    "OutsideFruit",
    "PlanStatus",
    "Planner",
    "PlantWall",
    "RandomPlanner",
    "RangeInformation",
    "StepLimit",
    "UntriedTerm",
    "ViewPlan",
    "WorkspaceSphere",
    "approach_activation",
    "build_constraints",
    "make_planner",
    "max_violation",
    "observation_information",
]


def make_planner(
    settings: Settings,
    loss: LossName,
    constraint_names: Sequence[ConstraintName],
    rng: np.random.Generator,
    extra_constraints: ExtraConstraints | None = None,
) -> Planner:
    """The planner ``settings.planner.kind`` selects, over the given task constraints."""
    kind = settings.planner.kind
    if kind == "bve":
        return BvePlanner(settings, loss, constraint_names, extra_constraints)
    if kind == "random":
        return RandomPlanner(settings, constraint_names, rng, extra_constraints)
    if kind == "fixed":
        return FixedViewsPlanner(settings, constraint_names, extra_constraints)
    return CirclePlanner(settings, constraint_names, extra_constraints)
