"""Sensor realism, seeded: image noise, the detector's intrinsic calibration error, joint
encoder noise. All off in ``SensorConfig()``; ``SensorConfig.realistic()`` turns them on."""

from __future__ import annotations

import numpy as np

from bve_mj.config import CameraConfig, SensorConfig
from bve_mj.perception.detection import Intrinsics

__all__ = ["calibrated_intrinsics", "noisy_encoders", "noisy_image"]


def noisy_image(image: np.ndarray, sensor: SensorConfig, rng: np.random.Generator) -> np.ndarray:
    """The image plus Gaussian noise of ``sensor.image_noise_std`` levels, clipped to uint8."""
    if sensor.image_noise_std == 0.0:
        return image
    noisy = image.astype(np.float32) + rng.normal(0.0, sensor.image_noise_std, image.shape).astype(np.float32)
    return np.clip(np.rint(noisy), 0, 255).astype(np.uint8)


def calibrated_intrinsics(camera: CameraConfig, sensor: SensorConfig, rng: np.random.Generator) -> Intrinsics:
    """What a calibration with the configured errors tells the detector (draw once per episode)."""
    return Intrinsics(
        camera.focal_px * (1.0 + rng.normal(0.0, sensor.focal_error_rel)),
        camera.width_px,
        camera.height_px,
        float(rng.normal(0.0, sensor.principal_point_error_px)),
        float(rng.normal(0.0, sensor.principal_point_error_px)),
    )


def noisy_encoders(q: np.ndarray, sensor: SensorConfig, rng: np.random.Generator) -> np.ndarray:
    """Joint angles as the encoders report them [rad]."""
    if sensor.encoder_noise_rad == 0.0:
        return np.asarray(q, dtype=float).copy()
    return np.asarray(q, dtype=float) + rng.normal(0.0, sensor.encoder_noise_rad, np.shape(q))
