"""Instance masks from another detector (a network's, as ultralytics or supervision give
them), measured as fruit behind the :class:`~bve_mj.perception.protocol.Detector` protocol.

Each mask's outline is cut into arcs and fitted as the built-in detector fits a ripe blob's
(:func:`~bve_mj.perception.outline_fit.measure_outline`: the cone fit trimmed of occluder
edges, the spheroid with the world's vertical, the checks); the covariance of (bearing,
apparent angular radius) comes from the fit's residuals and how much outline it saw (the
fit's and the arcs' jackknife σ), with the measurement's pixel σ (``centre_sigma_px``,
``radius_sigma_px``) as its floor, in quadrature. The target among the masks is chosen as
:mod:`bve_mj.perception.instance_choice` says; a mask of the wrong shape or dtype is a
refusal with the reason, never an exception."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from bve_mj.config import DetectorConfig, FruitPrior, MeasurementConfig, Settings
from bve_mj.perception.all_fruit import FruitDetections, Refusal
from bve_mj.perception.association import _blobs
from bve_mj.perception.detection import Detection, Intrinsics, NoDetection
from bve_mj.perception.instance_choice import _check_request, _Instance, _pick
from bve_mj.perception.instances import Arc, fruit_stretch, group_arcs, outline_arcs
from bve_mj.perception.outline_fit import measurable_fruit, measure_outline
from bve_mj.perception.protocol import DetectionRequest

__all__ = ["MaskDetector", "MaskSource", "check_masks"]

MaskSource = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]

"""An instance-mask detector: (H, W, 3) uint8 image → (masks (n, H, W) bool, confidence (n,))."""


def check_masks(
    masks: object, confidence: object, height_px: int, width_px: int
) -> tuple[np.ndarray, np.ndarray] | str:
    """A mask source's output as bool (n, H, W) (values > 0.5 are the instance: bool, 0/1,
    0/255 or probabilities) and float (n,), or why it is not one."""
    try:
        arr = np.asarray(masks)
        conf = np.asarray(confidence, dtype=float)
    except (TypeError, ValueError) as exc:
        return f"mask source output is not numeric arrays ({type(exc).__name__}: {exc})"
    if arr.size == 0 and conf.size == 0:
        return np.zeros((0, height_px, width_px), dtype=bool), np.zeros(0)
    if arr.ndim != 3 or arr.shape[1:] != (height_px, width_px):
        return f"mask source gave masks of shape {arr.shape}; expected (n, {height_px}, {width_px})"
    if arr.dtype == object or not (np.issubdtype(arr.dtype, np.number) or arr.dtype == bool):
        return f"mask source gave masks of dtype {arr.dtype}; expected bool or numbers"
    if conf.shape != (arr.shape[0],):
        n = arr.shape[0]
        return f"mask source gave confidences of shape {conf.shape} for {n} masks; expected ({n},)"
    return arr > 0.5, conf


class MaskDetector:
    """Instance masks from another detector, measured as fruit (the :class:`Detector` and
    :class:`EveryFruitDetector` protocols).

    Args:
        source: ``source(image_rgb) -> (masks, confidence)``: masks (n, H, W) of the image's
            size (bool; or numbers, > 0.5 the instance) and confidences (n,).
        fruit, measurement, config: as for the built-in detector (the fit, its checks and the
            floor of the covariance: ``measurement.centre_sigma_px``, ``radius_sigma_px``).
        min_confidence: masks less confident than this are not fruit.
    """

    def __init__(
        self,
        source: MaskSource,
        fruit: FruitPrior,
        measurement: MeasurementConfig | None = None,
        config: DetectorConfig | None = None,
        *,
        min_confidence: float = 0.25,
    ) -> None:
        self.source = source
        self.fruit = fruit
        self.measurement = measurement or MeasurementConfig()
        self.config = config or DetectorConfig()
        self.min_confidence = float(min_confidence)

    @classmethod
    def from_settings(cls, source: MaskSource, settings: Settings, **kwargs: float) -> MaskDetector:
        """A mask detector with ``settings``' fruit prior, measurement noise and detector
        settings as the rendered world resolves them (``kwargs``: ``min_confidence``)."""
        s = settings.for_world("mujoco")
        return cls(source, s.fruit, s.measurement, s.detector, **kwargs)

    def masks(self, image_rgb: np.ndarray, intrinsics: Intrinsics) -> tuple[np.ndarray, np.ndarray] | str:
        """The source's masks at least ``min_confidence`` confident, bool (n, H, W) and (n,),
        or why its output is not masks of this image."""
        masks, conf = self.source(image_rgb)
        out = check_masks(masks, conf, intrinsics.height_px, intrinsics.width_px)
        if isinstance(out, str):
            return out
        keep = out[1] >= self.min_confidence
        return out[0][keep], out[1][keep]

    def measure(self, mask: np.ndarray, request: DetectionRequest) -> Detection | NoDetection:
        """One instance mask (H, W) measured as a fruit, or why not."""
        intr = request.intrinsics
        m = np.asarray(mask)
        if m.shape != (intr.height_px, intr.width_px):
            return NoDetection(f"mask of shape {m.shape} is not ({intr.height_px}, {intr.width_px})")
        cfg = self.config
        mask8 = np.where(m > 0.5, 255, 0).astype(np.uint8)
        blobs = _blobs(mask8)
        if not blobs:
            return NoDetection("empty mask")
        H, W = mask8.shape
        arcs: list[Arc] = []
        for k, b in enumerate(blobs):
            o = b.outline
            usable = (o[:, 0] > 0) & (o[:, 0] < W - 1) & (o[:, 1] > 0) & (o[:, 1] < H - 1)
            arcs += outline_arcs(o + 0.5, usable, k, corner_px=cfg.corner_px, margin=cfg.junction_margin)
        largest = max(blobs, key=lambda b: b.area)
        up = request.up_camera if cfg.shape_grouping else None
        stretch = fruit_stretch(intr, up, self.fruit.shape_index, largest.centroid)
        found = group_arcs(
            arcs, tol_px=cfg.arc_tol_px, shape_rel=self.fruit.shape_spread_rel, stretch=stretch
        )
        if not found:
            return NoDetection("no stretch of the mask's outline is a circle arc (no fruit silhouette)")
        whole, part = measurable_fruit(found, cfg.min_arc_deg)
        # one instance, one fruit: the group with the longest outline
        chosen, seen = max(whole + part, key=lambda e: len(e[0].points))
        det = measure_outline(
            chosen,
            seen,
            blobs,
            mask8,
            (0, 0),
            intr,
            self.fruit,
            self.measurement,
            cfg,
            up_camera=request.up_camera,
        )
        if isinstance(det, NoDetection):
            return det
        f = intr.focal_px
        sc = (
            math.hypot(
                self.measurement.centre_sigma_px,
                det.centre_fit_px,
                det.centre_jackknife_px,
                det.centre_disagreement_px,
            )
            / f
        )
        sr = math.hypot(self.measurement.radius_sigma_px, det.radius_fit_px, det.radius_jackknife_px) / f
        return replace(det, measurement_cov=np.diag([sc * sc, sc * sc, sr * sr]))

    def detect(self, image_rgb: np.ndarray, request: DetectionRequest) -> Detection | NoDetection:
        problem = _check_request(image_rgb, request.intrinsics)
        if problem is not None:
            return NoDetection(problem)
        out = self.masks(image_rgb, request.intrinsics)
        if isinstance(out, str):
            return NoDetection(out)
        masks, conf = out
        instances = []
        for k, (m, c) in enumerate(zip(masks, conf, strict=True)):
            vs, us = np.nonzero(m)
            if len(us) == 0:
                continue
            centre = np.array([us.mean() + 0.5, vs.mean() + 0.5])
            instances.append(_Instance(centre, math.sqrt(len(us) / math.pi), float(c), k))
        if not instances:
            return NoDetection(
                "no mask from the detector" if len(masks) == 0 else "only empty masks from the detector"
            )
        chosen = _pick(instances, request, self.fruit, self.config)
        if isinstance(chosen, NoDetection):
            return chosen
        return self.measure(masks[chosen.index], request)

    def detect_all(
        self, image_rgb: np.ndarray, request: DetectionRequest, *, max_range_m: float | None = None
    ) -> FruitDetections:
        problem = _check_request(image_rgb, request.intrinsics)
        out = self.masks(image_rgb, request.intrinsics) if problem is None else problem
        if isinstance(out, str):
            return FruitDetections((), (Refusal(None, None, out),))
        detections: list[Detection] = []
        refused: list[Refusal] = []
        for m in out[0]:
            if not m.any():
                continue
            det = self.measure(m, request)
            if isinstance(det, Detection):
                if max_range_m is None or det.range_m <= max_range_m:
                    detections.append(det)
            else:
                vs, us = np.nonzero(m)
                centre = np.array([us.mean() + 0.5, vs.mean() + 0.5])
                refused.append(Refusal(centre, math.sqrt(len(us) / math.pi), det.reason))
        detections.sort(key=lambda d: -d.radius_px)
        return FruitDetections(tuple(detections), tuple(refused))
