"""The detector protocol: what any detector takes (an image and what the estimate predicts of
the view) and gives (a :class:`~bve_mj.perception.detection.Detection` of the target, with its
measurement and covariance, or a :class:`~bve_mj.perception.detection.NoDetection` saying
why), so that the rendered world (:class:`bve_mj.sim.mujoco_world.MujocoWorld`) measures
with whichever detector it is given.

- :class:`BuiltinDetector`: the colour detector (:func:`~bve_mj.perception.detector.detect`,
  :func:`~bve_mj.perception.all_fruit.detect_all`), its covariance from the calibrated noise
  model (:mod:`bve_mj.estimation.noise`).
- :class:`~bve_mj.perception.adapters.BoxDetector` and
  :class:`~bve_mj.perception.adapters.MaskDetector`: bounding boxes or instance masks from
  another detector (a network), each turned into the same measurement with a covariance from
  the box's or the mask's own noise.
- :func:`detector_from_settings`: the one ``detector.kind`` names.

A detector that measures every fruit in view, not only the one the estimate means (the
every-fruit loop, ``--fruits all``), implements :class:`EveryFruitDetector` as well."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from bve_mj.config import DetectorConfig, FruitPrior, MeasurementConfig
from bve_mj.perception.all_fruit import FruitDetections, detect_all
from bve_mj.perception.detection import Detection, Intrinsics, NoDetection, Prediction
from bve_mj.perception.detector import detect

__all__ = [
    "BuiltinDetector",
    "DetectionRequest",
    "Detector",
    "EveryFruitDetector",
    "detector_from_settings",
]


@dataclass(frozen=True)
class DetectionRequest:
    """What a detector is told about a view besides its image.

    Attributes:
        intrinsics: the camera as the estimator knows it (the image's size must match).
        prediction: the estimate of the target in the camera frame with its covariance
            (x optical axis, y left, z up) [m]: it picks the target among the fruit in view.
        predicted_px: where the estimate projects (u, v) [px], when there is no covariance
            to pick with (ignored with ``prediction``).
        up_camera: the world's vertical in the camera frame, unit (3,), if known: the fruit's
            axis (a tomato is a spheroid about it).
    """

    intrinsics: Intrinsics
    prediction: Prediction | None = None
    predicted_px: np.ndarray | None = None
    up_camera: np.ndarray | None = None


@runtime_checkable
class Detector(Protocol):
    """Measures the target fruit in an image.

    ``detect`` returns a :class:`Detection` (bearing of the centre, apparent angular radius,
    the centre in the camera frame with its covariance ``cov_camera`` and, when the detector
    states its own noise, ``measurement_cov``, the covariance of (bearing, apparent size)), or
    a :class:`NoDetection` with the reason: a refusal, never an exception, for anything the
    image or the detector's own output gets wrong."""

    def detect(self, image_rgb: np.ndarray, request: DetectionRequest) -> Detection | NoDetection:
        """The target in ``image_rgb`` ((H, W, 3) uint8), or why not."""
        ...


@runtime_checkable
class EveryFruitDetector(Detector, Protocol):
    """A detector that also measures every fruit in view (for the every-fruit loop)."""

    def detect_all(
        self, image_rgb: np.ndarray, request: DetectionRequest, *, max_range_m: float | None = None
    ) -> FruitDetections:
        """Every fruit measured in ``image_rgb`` and those refused (a fruit measured farther
        than ``max_range_m`` [m], when given, is dropped); ``request.prediction`` and
        ``predicted_px`` are not used."""
        ...


@dataclass(frozen=True)
class BuiltinDetector:
    """The built-in colour detector behind the :class:`Detector` protocol.

    Attributes:
        fruit: the fruit prior (its radius turns the apparent size into a range).
        measurement: the measurement noise its ``cov_camera`` is made with.
        config: the detector's settings.
    Its detections carry no ``measurement_cov``: the calibrated noise model gives it."""

    fruit: FruitPrior
    measurement: MeasurementConfig
    config: DetectorConfig

    def detect(self, image_rgb: np.ndarray, request: DetectionRequest) -> Detection | NoDetection:
        return detect(
            image_rgb,
            request.intrinsics,
            self.fruit,
            self.measurement,
            self.config,
            request.predicted_px,
            prediction=request.prediction,
            up_camera=request.up_camera,
        )

    def detect_all(
        self, image_rgb: np.ndarray, request: DetectionRequest, *, max_range_m: float | None = None
    ) -> FruitDetections:
        return detect_all(
            image_rgb,
            request.intrinsics,
            self.fruit,
            self.measurement,
            self.config,
            up_camera=request.up_camera,
            max_range_m=max_range_m,
        )


def detector_from_settings(
    config: DetectorConfig,
    fruit: FruitPrior,
    measurement: MeasurementConfig,
    *,
    true_boxes: Callable[[], np.ndarray] | None = None,
    image_size_px: tuple[int, int] | None = None,
    rng: np.random.Generator | None = None,
) -> EveryFruitDetector:
    """The detector ``config.kind`` names.

    Args:
        config, fruit, measurement: the detector's settings, the fruit prior and the
            measurement noise (the built-in detector's covariance).
        true_boxes: ``synthetic_boxes`` only: the true boxes (n, 4) [px] of the fruit in the
            current view, from the scene's ground truth (the world provides it).
        image_size_px: ``synthetic_boxes`` only: (width, height) of the images [px].
        rng: ``synthetic_boxes`` only: the stream of its noise, misses and false positives.
    Raises:
        ValueError: ``synthetic_boxes`` without its ground truth, size or stream.
    """
    if config.kind == "builtin":
        return BuiltinDetector(fruit, measurement, config)
    from bve_mj.perception.adapters import BoxDetector
    from bve_mj.perception.synthetic_boxes import SyntheticBoxes

    if true_boxes is None or image_size_px is None or rng is None:
        raise ValueError(
            "detector.kind = synthetic_boxes needs the scene's true boxes, the image size and a stream"
        )
    source = SyntheticBoxes(
        true_boxes,
        image_size_px,
        rng,
        noise_px=config.box_noise_px,
        miss_p=config.miss_p,
        false_positives=config.false_positives,
    )
    # the adapter declares the noise the boxes have (never below a quantised corner's)
    return BoxDetector(source, fruit, config, corner_sigma_px=max(config.box_noise_px, 0.5))
