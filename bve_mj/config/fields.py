"""What every section shares: the allowed values of each choice (each defined here, once),
and the checks that reject a value with one line naming the field and what is allowed."""

from __future__ import annotations

import math
from typing import Any, Literal, get_args

import numpy as np

from bve_mj.errors import ConfigError

__all__ = [
    "MAX_COUNT",
    "MAX_MAGNITUDE",
    "ConstraintName",
    "DetectorKind",
    "FilterKind",
    "Formulation",
    "FruitType",
    "FruitsMode",
    "JointLimitSet",
    "LossName",
    "MeasurementKind",
    "OptimiserName",
    "OtherTrussesRipeness",
    "PlannerKind",
    "PlanningModel",
    "PriorKind",
    "PriorSource",
    "RipenessName",
    "RobotName",
    "StateKind",
    "TrussLayout",
    "WorldName",
]

MeasurementKind = Literal["auto", "range", "camera"]


FilterKind = Literal["ekf", "ukf"]


DetectorKind = Literal["builtin", "synthetic_boxes"]


StateKind = Literal["auto", "centre", "centre_radius"]


WorldName = Literal["synthetic", "mujoco"]


LossName = Literal["dispersion", "max_eigenvalue"]


OptimiserName = Literal["slsqp", "trust-constr"]


PlanningModel = Literal["paper", "consistent"]


PlannerKind = Literal["bve", "random", "circle", "fixed"]


PriorSource = Literal["auto", "filter", "views"]


PriorKind = Literal["detection", "cube"]


RobotName = Literal["manipulator_h", "ur5", "panda"]


JointLimitSet = Literal["auto", "urdf", "emanual"]


Formulation = Literal["joint", "cartesian"]
ConstraintName = Literal["band", "workspace", "outside_fruit", "cone", "wall"]


def _why(text: str, unit: str = "") -> dict[str, str]:
    return {"why": text, "unit": unit}


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


FruitsMode = Literal["target", "all"]


OtherTrussesRipeness = Literal["unripe", "mixed"]


def _int_at_least(section: str, name: str, value: Any, low: int) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not low <= value <= MAX_COUNT:
        raise ConfigError(f"{section}.{name}", value, f"an integer in [{low}, {MAX_COUNT}]")


def _optional_range(
    section: str, name: str, value: Any, lo: float = -math.inf, hi: float = math.inf
) -> tuple[float, float] | None:
    return None if value is None else _range(section, name, value, lo, hi)
