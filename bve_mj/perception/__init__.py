"""Perception: the tomato detector and the measurement it makes."""

from bve_mj.perception.detector import (
    Detection,
    Intrinsics,
    NoDetection,
    Prediction,
    detect,
    red_mask,
    ripe_mask,
)

__all__ = ["Detection", "Intrinsics", "NoDetection", "Prediction", "detect", "red_mask", "ripe_mask"]
