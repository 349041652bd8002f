"""Bring your own detector: bounding boxes or instance masks from another detector (a network,
as ultralytics or supervision give them) measured as the built-in detector measures, behind
the :class:`~bve_mj.perception.protocol.Detector` protocol.

- :class:`BoxDetector`: a box source, ``source(image) -> (xyxy (n, 4) [px], confidence (n,))``.
  Each box is the image of a spheroid (:func:`~bve_mj.perception.box_geometry.fit_box`): the
  bearing of its centre and its apparent angular radius, with the covariance of independent
  corner errors of ``corner_sigma_px`` (near the optical axis: centre σ = σ_px / √2 per
  coordinate, apparent radius σ = σ_px / 2) plus the prior's unknown shape index.
- :class:`MaskDetector` (:mod:`bve_mj.perception.mask_adapter`): a mask source,
  ``source(image) -> (masks (n, H, W) bool, confidence (n,))``. Each mask's outline is cut
  into arcs and fitted as the built-in detector fits a ripe blob's
  (:func:`~bve_mj.perception.outline_fit.measure_outline`: the cone fit trimmed of occluder
  edges, the spheroid with the world's vertical, the checks); the covariance comes from the
  fit's residuals and how much outline it saw (the fit's and the arcs' jackknife σ), with
  the measurement's pixel σ (``centre_sigma_px``, ``radius_sigma_px``) as its floor, in
  quadrature.

Which instance is the target (:mod:`bve_mj.perception.instance_choice`): with a prediction
(the estimate and its covariance in the camera frame), the one nearest in 3-D Mahalanobis
distance (each instance's rough centre: its circle's bearing, the range from its size and
the prior's radius, generous covariance), gated at χ²(3) 0.9999 (nothing nearer: no
detection) and "ambiguous" when another is about as likely, as the built-in detector
decides; with only a predicted pixel, the instance whose centre is nearest to it; with
neither, the most confident. Its measurement is then made, or refused with the reason: a box
cut by the image edge (its extent is not the fruit's), a box no fruit projects to, a mask of
the wrong shape, too little outline. Bad output of the source (a wrong shape, non-finite
numbers) is a refusal too, never an exception.

Frames: the paper's camera frame (x optical axis, y left, z up); pixels u right, v down,
continuous (pixel i spans [i, i + 1))."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from bve_mj.config import DetectorConfig, FruitPrior, Settings
from bve_mj.perception.all_fruit import FruitDetections, Refusal
from bve_mj.perception.association import _along_across
from bve_mj.perception.box_geometry import fit_box
from bve_mj.perception.detection import Detection, Intrinsics, NoDetection
from bve_mj.perception.instance_choice import _check_request, _Instance, _pick
from bve_mj.perception.mask_adapter import MaskDetector, MaskSource, check_masks
from bve_mj.perception.protocol import DetectionRequest

__all__ = ["BoxDetector", "BoxSource", "MaskDetector", "MaskSource", "check_boxes", "check_masks"]

BoxSource = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]

"""A box detector: (H, W, 3) uint8 image → (xyxy (n, 4) [px], confidence (n,))."""

_EDGE_PX = 1.0  # a box edge within this of the image border is cut by it


def check_boxes(xyxy: object, confidence: object) -> tuple[np.ndarray, np.ndarray] | str:
    """A box source's output as float arrays (n, 4) and (n,), or why it is not one. An empty
    output (no box) may be any array of size 0."""
    try:
        boxes = np.asarray(xyxy, dtype=float)
        conf = np.asarray(confidence, dtype=float)
    except (TypeError, ValueError) as exc:
        return f"box source output is not numeric arrays ({type(exc).__name__}: {exc})"
    if boxes.size == 0 and conf.size == 0:
        return np.zeros((0, 4)), np.zeros(0)
    if boxes.ndim != 2 or boxes.shape[1] != 4:
        return f"box source gave xyxy of shape {boxes.shape}; expected (n, 4)"
    if conf.shape != (boxes.shape[0],):
        n = boxes.shape[0]
        return f"box source gave confidences of shape {conf.shape} for {n} boxes; expected ({n},)"
    return boxes, conf


class BoxDetector:
    """Bounding boxes from another detector, measured as fruit (the :class:`Detector` and
    :class:`EveryFruitDetector` protocols).

    Args:
        source: ``source(image_rgb) -> (xyxy, confidence)``: boxes (n, 4) as (u_min, v_min,
            u_max, v_max) [px] in the image's pixels and their confidences (n,) (numpy
            arrays, or anything ``numpy.asarray`` reads: a CPU tensor, a list).
        fruit: the fruit prior: its radius turns the apparent size into a range, its shape
            index (and spread) the box into a spheroid.
        config: the detector settings used here: ``min_radius_px`` (smaller boxes are
            specks) and ``ambiguity_ratio``.
        corner_sigma_px: 1σ of each box corner coordinate [px] (the source's noise: measure
            it against labelled boxes, as ``bve-mj calibrate`` does for the built-in detector).
        min_confidence: boxes less confident than this are not fruit.
    """

    def __init__(
        self,
        source: BoxSource,
        fruit: FruitPrior,
        config: DetectorConfig | None = None,
        *,
        corner_sigma_px: float = 2.0,
        min_confidence: float = 0.25,
    ) -> None:
        if not (math.isfinite(corner_sigma_px) and corner_sigma_px > 0.0):
            raise ValueError(f"corner_sigma_px must be a number > 0, got {corner_sigma_px!r}")
        self.source = source
        self.fruit = fruit
        self.config = config or DetectorConfig()
        self.corner_sigma_px = float(corner_sigma_px)
        self.min_confidence = float(min_confidence)

    @classmethod
    def from_settings(cls, source: BoxSource, settings: Settings, **kwargs: float) -> BoxDetector:
        """A box detector with ``settings``' fruit prior and detector settings as the rendered
        world resolves them (a ``[fruit]`` section left at its defaults is the prior of the
        scene's fruit type) (``kwargs``: ``corner_sigma_px``, ``min_confidence``)."""
        s = settings.for_world("mujoco")
        return cls(source, s.fruit, s.detector, **kwargs)

    def boxes(self, image_rgb: np.ndarray) -> tuple[np.ndarray, np.ndarray] | str:
        """The source's boxes at least ``min_confidence`` confident, (n, 4) and (n,), or why
        its output is not boxes."""
        out = check_boxes(*self.source(image_rgb))
        if isinstance(out, str):
            return out
        boxes, conf = out
        keep = conf >= self.min_confidence
        return boxes[keep], conf[keep]

    def measure(self, xyxy: np.ndarray, request: DetectionRequest) -> Detection | NoDetection:
        """One box (u_min, v_min, u_max, v_max) [px] measured as a fruit, or why not."""
        intr = request.intrinsics
        box = np.asarray(xyxy, dtype=float).reshape(-1)
        if box.shape != (4,) or not np.all(np.isfinite(box)):
            return NoDetection(f"box {box.tolist()} is not 4 finite numbers")
        u0, v0, u1, v1 = (float(x) for x in box)
        W, H = intr.width_px, intr.height_px
        if u1 <= u0 or v1 <= v0:
            return NoDetection(f"box {box.round(1).tolist()} is empty (u_max <= u_min or v_max <= v_min)")
        if u1 <= 0.0 or v1 <= 0.0 or u0 >= W or v0 >= H:
            return NoDetection(f"box {box.round(1).tolist()} lies outside the {W}x{H} image")
        if u0 < _EDGE_PX or v0 < _EDGE_PX or u1 > W - _EDGE_PX or v1 > H - _EDGE_PX:
            return NoDetection(
                f"box {box.round(1).tolist()} is cut by the image edge: its extent is not the fruit's"
            )
        if 0.25 * (u1 - u0 + v1 - v0) < self.config.min_radius_px:
            return NoDetection(f"a speck, not a fruit: box {u1 - u0:.1f}x{v1 - v0:.1f} px")
        fruit = self.fruit
        shape_sigma = fruit.shape_index * fruit.shape_spread_rel / math.sqrt(3.0)
        fit = fit_box(
            box,
            intr,
            self.corner_sigma_px,
            up_camera=request.up_camera,
            shape_index=fruit.shape_index,
            shape_sigma=shape_sigma,
        )
        if isinstance(fit, str):
            return NoDetection(fit)
        return _detection(fit.z, fit.cov_z, fit.centre_px, intr, fruit, area_px=int((u1 - u0) * (v1 - v0)))

    def detect(self, image_rgb: np.ndarray, request: DetectionRequest) -> Detection | NoDetection:
        problem = _check_request(image_rgb, request.intrinsics)
        if problem is not None:
            return NoDetection(problem)
        out = self.boxes(image_rgb)
        if isinstance(out, str):
            return NoDetection(out)
        boxes, conf = out
        instances = [
            _Instance(
                np.array([0.5 * (b[0] + b[2]), 0.5 * (b[1] + b[3])]), 0.25 * (b[2] - b[0] + b[3] - b[1]), c, k
            )
            for k, (b, c) in enumerate(zip(boxes, conf, strict=True))
            if np.all(np.isfinite(b)) and b[2] > b[0] and b[3] > b[1]
        ]
        if not instances:
            return NoDetection(
                "no box from the detector" if len(boxes) == 0 else "no valid box from the detector"
            )
        chosen = _pick(instances, request, self.fruit, self.config)
        if isinstance(chosen, NoDetection):
            return chosen
        return self.measure(boxes[chosen.index], request)

    def detect_all(
        self, image_rgb: np.ndarray, request: DetectionRequest, *, max_range_m: float | None = None
    ) -> FruitDetections:
        problem = _check_request(image_rgb, request.intrinsics)
        out = self.boxes(image_rgb) if problem is None else problem
        if isinstance(out, str):
            return FruitDetections((), (Refusal(None, None, out),))
        detections: list[Detection] = []
        refused: list[Refusal] = []
        for b in out[0]:
            det = self.measure(b, request)
            if isinstance(det, Detection):
                if max_range_m is None or det.range_m <= max_range_m:
                    detections.append(det)
            else:
                ok = bool(np.all(np.isfinite(b)))
                centre = np.array([0.5 * (b[0] + b[2]), 0.5 * (b[1] + b[3])]) if ok else None
                radius = 0.25 * float(b[2] - b[0] + b[3] - b[1]) if ok else None
                refused.append(Refusal(centre, radius, det.reason))
        detections.sort(key=lambda d: -d.radius_px)
        return FruitDetections(tuple(detections), tuple(refused))


def _detection(
    z: np.ndarray,
    cov_z: np.ndarray,
    centre_px: np.ndarray,
    intrinsics: Intrinsics,
    fruit: FruitPrior,
    *,
    area_px: int,
) -> Detection:
    """A :class:`Detection` from z = (a_y/a_x, a_z/a_x, α) and its covariance: the bearing, the
    range from the prior's radius, and the centre's covariance in the camera frame (lateral
    from the bearing's σ, range from the unknown radius and α's σ, as the built-in's)."""
    f = intrinsics.focal_px
    a0, b0, alpha = (float(x) for x in z)
    axis = np.array([1.0, a0, b0]) / math.sqrt(1.0 + a0 * a0 + b0 * b0)
    rho = fruit.radius_m / math.sin(alpha)
    sigma_bearing = math.sqrt(max(float(np.linalg.eigvalsh(cov_z[:2, :2])[-1]), 0.0)) * float(axis[0]) ** 2
    sigma_alpha = math.sqrt(max(float(cov_z[2, 2]), 0.0))
    sigma_lat = rho * sigma_bearing
    sigma_rho = rho * math.hypot(fruit.size_spread_rel, sigma_alpha / math.tan(alpha))
    return Detection(
        centre_px=np.asarray(centre_px, dtype=float),
        radius_px=f * math.tan(alpha),
        bearing_camera=axis,
        angular_radius_rad=alpha,
        range_m=rho,
        p_camera=rho * axis,
        cov_camera=_along_across(axis, sigma_rho, sigma_lat),
        area_px=area_px,
        boundary_points=0,
        trimmed_fraction=0.0,
        arc_deg=360.0,
        centre_fit_px=float(f * sigma_bearing),
        radius_fit_px=float(f * sigma_alpha),
        measurement_cov=np.array(cov_z, dtype=float),
    )
