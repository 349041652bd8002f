"""Estimation: Gaussian belief, measurement models, EKF predict/update."""

from bve_mj.estimation.belief import Belief
from bve_mj.estimation.ekf import UpdateResult, nis_threshold, predict, update
from bve_mj.estimation.models import CameraModel, MeasurementModel, RangeModel

__all__ = [
    "Belief",
    "CameraModel",
    "MeasurementModel",
    "RangeModel",
    "UpdateResult",
    "nis_threshold",
    "predict",
    "update",
]
