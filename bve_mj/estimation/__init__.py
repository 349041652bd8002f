"""Estimation: Gaussian belief, measurement models, EKF and UKF predict/update."""

from collections.abc import Callable
from functools import partial
from typing import Literal

from bve_mj.estimation import ukf
from bve_mj.estimation.belief import CALIBRATION, CENTRE, RADIUS, STATE_DIMS, Belief
from bve_mj.estimation.ekf import UpdateResult, nis_threshold, predict, update
from bve_mj.estimation.models import BearingSizeModel, CameraModel, MeasurementModel, RangeModel, SizeModel

__all__ = [
    "CALIBRATION",
    "CENTRE",
    "RADIUS",
    "STATE_DIMS",
    "BearingSizeModel",
    "Belief",
    "CameraModel",
    "MeasurementModel",
    "RangeModel",
    "SizeModel",
    "UpdateResult",
    "filter_update",
    "nis_threshold",
    "predict",
    "update",
]


def filter_update(kind: Literal["ekf", "ukf"], iterations: int = 1) -> Callable[..., UpdateResult]:
    """The update step of filter ``kind``, iterated ``iterations`` times at most: the EKF's
    (:func:`update`) or the UKF's (:func:`bve_mj.estimation.ukf.update`); both take (belief,
    z, model, gate_probability)."""
    if kind == "ukf":
        return partial(ukf.update, iterations=iterations)
    return partial(update, iterations=iterations)
