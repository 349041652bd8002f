"""Which instance of another detector's output is the target: the rule both adapters
(:mod:`bve_mj.perception.adapters`, :mod:`bve_mj.perception.mask_adapter`) share.

With a prediction (the estimate and its covariance in the camera frame), the instance nearest
in 3-D Mahalanobis distance (each instance's rough centre: its circle's bearing, the range from
its size and the prior's radius, generous covariance), gated at χ²(3) 0.9999 (nothing nearer:
no detection) and "ambiguous" when another is about as likely, as the built-in detector
decides; with only a predicted pixel, the instance whose centre is nearest to it; with
neither, the most confident."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from bve_mj.config import DetectorConfig, FruitPrior
from bve_mj.perception.association import _rough_measurement
from bve_mj.perception.detection import _CHI2_3_999, Intrinsics, NoDetection, Prediction
from bve_mj.perception.instances import Circle
from bve_mj.perception.masks import _check_image
from bve_mj.perception.protocol import DetectionRequest

__all__: list[str] = []  # used by the adapters only

_GATE_CHI2 = 21.108  # χ²(3) quantile at 0.9999: an instance the estimate allows at all


@dataclass(frozen=True)
class _Instance:
    """One instance of the source's output: its rough circle (centre, radius [px]) and
    confidence, and its index in that output."""

    centre_px: np.ndarray
    radius_px: float
    confidence: float
    index: int


def _usable_prediction(request: DetectionRequest) -> Prediction | None:
    p = request.prediction
    if p is None:
        return None
    m = np.asarray(p.p_camera, dtype=float)
    P = np.asarray(p.cov_camera, dtype=float)
    if (
        m.shape != (3,)
        or P.shape != (3, 3)
        or not (np.all(np.isfinite(m)) and np.all(np.isfinite(P)))
        or m[0] <= 1e-3
    ):
        return None  # behind the camera: it cannot pick a fruit
    return Prediction(m, P)


def _pick(
    instances: list[_Instance], request: DetectionRequest, fruit: FruitPrior, cfg: DetectorConfig
) -> _Instance | NoDetection:
    """The instance the request means (see the module's docstring), or why none."""
    if not instances:
        return NoDetection("no instance from the detector")
    prediction = _usable_prediction(request)
    if prediction is not None:
        scored = []
        for inst in instances:
            rough = _rough_measurement(Circle(inst.centre_px, inst.radius_px), request.intrinsics, fruit)
            if rough is None:
                continue
            z, R = rough
            nu = z - prediction.p_camera
            scored.append((float(nu @ np.linalg.solve(prediction.cov_camera + R, nu)), inst, (z, R)))
        if not scored:
            return NoDetection("no instance in front of the camera")
        scored.sort(key=lambda e: e[0])
        d2_best, best, rough_best = scored[0]
        if d2_best > _GATE_CHI2:
            return NoDetection(
                f"no instance the estimate allows: the nearest is at Mahalanobis^2 {d2_best:.1f} "
                f"> {_GATE_CHI2:g}"
            )
        margin = 2.0 * math.log(cfg.ambiguity_ratio)
        for d2, other, rough in scored[1:]:
            apart = float(np.linalg.norm(other.centre_px - best.centre_px))
            if apart <= 0.5 * max(best.radius_px, other.radius_px):
                continue  # the same fruit twice (overlapping boxes or masks)
            if d2 <= _CHI2_3_999 and d2 - d2_best < margin:
                return NoDetection(
                    f"ambiguous: two fruit fit the estimate (Mahalanobis^2 {d2_best:.1f} and {d2:.1f}, "
                    f"likelihood ratio {math.exp(0.5 * (d2 - d2_best)):.1f} < {cfg.ambiguity_ratio:g})",
                    (rough_best, rough),
                )
            break  # sorted: the rest are less likely still
        return best
    predicted = request.predicted_px
    if predicted is not None:
        at = np.asarray(predicted, dtype=float).reshape(-1)
        if at.shape == (2,) and np.all(np.isfinite(at)):
            return min(instances, key=lambda i: float(np.linalg.norm(i.centre_px - at)))
    return max(instances, key=lambda i: (i.confidence, i.radius_px))


def _check_request(image_rgb: np.ndarray, intrinsics: Intrinsics) -> str | None:
    problem = _check_image(image_rgb)
    if problem is None and (intrinsics.height_px, intrinsics.width_px) != image_rgb.shape[:2]:
        problem = f"image {image_rgb.shape[1]}x{image_rgb.shape[0]} does not match the intrinsics"
    return problem
