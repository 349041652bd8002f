"""Perception: the detector protocol, the built-in tomato detector, adapters for boxes and masks
from other detectors, and the measurement each makes."""

from bve_mj.perception.adapters import BoxDetector, BoxSource, MaskDetector, MaskSource
from bve_mj.perception.all_fruit import FruitDetections, Refusal, detect_all
from bve_mj.perception.box_geometry import BoxFit, ellipsoid_box, fit_box
from bve_mj.perception.detection import Detection, Intrinsics, NoDetection, Prediction
from bve_mj.perception.detector import detect
from bve_mj.perception.masks import red_mask, ripe_mask
from bve_mj.perception.protocol import (
    BuiltinDetector,
    DetectionRequest,
    Detector,
    EveryFruitDetector,
    detector_from_settings,
)
from bve_mj.perception.synthetic_boxes import SyntheticBoxes

__all__ = [
    "BoxDetector",
    "BoxFit",
    "BoxSource",
    "BuiltinDetector",
    "Detection",
    "DetectionRequest",
    "Detector",
    "EveryFruitDetector",
    "FruitDetections",
    "Intrinsics",
    "MaskDetector",
    "MaskSource",
    "NoDetection",
    "Prediction",
    "Refusal",
    "SyntheticBoxes",
    "detect",
    "detect_all",
    "detector_from_settings",
    "ellipsoid_box",
    "fit_box",
    "red_mask",
    "ripe_mask",
]
