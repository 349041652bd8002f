"""Perception: the tomato detector and the measurement it makes."""

from bve_mj.perception.all_fruit import FruitDetections, Refusal, detect_all
from bve_mj.perception.detection import Detection, Intrinsics, NoDetection, Prediction
from bve_mj.perception.detector import detect
from bve_mj.perception.masks import red_mask, ripe_mask

__all__ = [
    "Detection",
    "FruitDetections",
    "Intrinsics",
    "NoDetection",
    "Prediction",
    "Refusal",
    "detect",
    "detect_all",
    "red_mask",
    "ripe_mask",
]
