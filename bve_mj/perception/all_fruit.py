"""Every ripe fruit in an image, each measured as the single-target detector measures its target.

For multi-fruit tracking there is no prediction to pick a target with: every ripe fruit in
view is measured. The image is segmented once (:func:`~bve_mj.perception.masks.ripe_mask`);
the outline of every ripe blob is cut into arcs at its corners and the arcs are grouped
into fruit (:mod:`bve_mj.perception.instances`) exactly as :func:`~bve_mj.perception.detector.detect`
groups them around the blob its prediction falls on: with the blob's neighbouring fragments
(a fruit split by a stem is one fruit), its partial outlines that lie inside a measurable
fruit's circle dropped (the edges of a calyx or stem over it). A fruit found twice (from two
blobs' neighbourhoods, or as two groups of arcs whose circles are less than half a radius
apart) is measured once. Each fruit then goes through the same fit and checks as ``detect``'s
target (:func:`~bve_mj.perception.outline_fit.measure_outline`) but for the expected-size
check (no prediction, no expected size): a merged blob is refused, never one fruit.

Frames: the paper's camera frame (x optical axis, y left, z up); pixels u right, v down."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from bve_mj.config import DetectorConfig, FruitPrior, MeasurementConfig
from bve_mj.perception.association import _Blob, _blobs, _inside, _nearby
from bve_mj.perception.detection import Detection, Intrinsics
from bve_mj.perception.instances import Arc, FruitOutline, fruit_stretch, group_arcs, outline_arcs
from bve_mj.perception.masks import _check_image, ripe_mask
from bve_mj.perception.outline_fit import measurable_fruit, measure_outline
from bve_mj.perception.rims import interior_arcs, interior_edges

__all__ = ["FruitDetections", "Refusal", "detect_all"]

_MIN_SEED = 8  # the shortest arc that seeds a fruit in group_arcs (its default min_seed)


@dataclass(frozen=True)
class Refusal:
    """A fruit found in the image but not measured, and why.

    Attributes:
        centre_px: the centre (u, v) of the circle its outline arcs lie on [px], (2,); None
            when the whole image was refused (wrong shape or dtype).
        radius_px: that circle's radius [px]; None with ``centre_px``.
        reason: why (as :class:`~bve_mj.perception.detection.NoDetection` says it).
        partial: a fruit seen only in part (``NoDetection.partial``): evidence of a fruit
            that could not be measured, where a fragment or a merged blob is none.
    """

    centre_px: np.ndarray | None
    radius_px: float | None
    reason: str
    partial: bool = False


@dataclass(frozen=True)
class FruitDetections:
    """Every ripe fruit of an image: those measured and those refused.

    Attributes:
        detections: one :class:`~bve_mj.perception.detection.Detection` per fruit measured,
            longest visible outline first.
        refused: the fruit found but not measured (too little outline, a merged blob, a poor
            fit ...), or one refusal of the whole image (a bad image).
    An image without ripe colour gives neither.
    """

    detections: tuple[Detection, ...]
    refused: tuple[Refusal, ...]


def detect_all(
    image_rgb: np.ndarray,
    intrinsics: Intrinsics,
    fruit: FruitPrior,
    measurement: MeasurementConfig,
    config: DetectorConfig | None = None,
    *,
    up_camera: np.ndarray | None = None,
    max_range_m: float | None = None,
) -> FruitDetections:
    """Measure every ripe fruit in an RGB image.

    Args:
        image_rgb: (H, W, 3) uint8, H and W those of ``intrinsics``.
        intrinsics, fruit, measurement, config: as for :func:`~bve_mj.perception.detector.detect`
            (the fruit prior's radius turns each apparent size into a range).
        up_camera: the world's vertical in the camera frame (x optical axis, y left, z up;
            unit, (3,)), if known: each fruit is fitted as a spheroid with that axis.
        max_range_m: when given, a fruit measured farther than this [m] (range from the
            prior radius) is dropped: a fruit of the next row, not one to track.
    Returns:
        the fruit measured and those refused (never raises on a bad image: it is one
        refusal, with the reason).
    """
    cfg = config or DetectorConfig()
    problem = _check_image(image_rgb)
    if problem is None and (intrinsics.height_px, intrinsics.width_px) != image_rgb.shape[:2]:
        problem = f"image {image_rgb.shape[1]}x{image_rgb.shape[0]} does not match the intrinsics"
    if problem is not None:
        return FruitDetections((), (Refusal(None, None, problem),))
    mask = ripe_mask(image_rgb, cfg)
    every = _blobs(mask)
    detections: list[Detection] = []
    refused: list[Refusal] = []
    rims: list[Arc] = []
    if cfg.interior_edge > 0.0:  # rims over a ripe neighbour: edges inside the mask
        chains = interior_edges(image_rgb, mask, cfg.interior_edge)
        rims = interior_arcs(chains, [b.outline for b in every])

    def stretch(at_px: np.ndarray) -> np.ndarray | None:
        up = up_camera if cfg.shape_grouping else None
        return fruit_stretch(intrinsics, up, fruit.shape_index, at_px)

    for outline, seen in _every_fruit(every, mask.shape, cfg, fruit.shape_spread_rel, rims, stretch):
        det = measure_outline(
            outline, seen, every, mask, (0, 0), intrinsics, fruit, measurement, cfg, up_camera=up_camera
        )
        if isinstance(det, Detection):
            if max_range_m is None or det.range_m <= max_range_m:
                detections.append(det)
        else:
            circle = outline.circle
            refused.append(Refusal(circle.centre.copy(), circle.radius, det.reason, det.partial))
    return FruitDetections(tuple(detections), tuple(refused))


def _every_fruit(
    every: list[_Blob],
    shape: tuple[int, ...],
    cfg: DetectorConfig,
    shape_rel: float,
    rims: Sequence[Arc] = (),
    stretch: Callable[[np.ndarray], np.ndarray | None] | None = None,
) -> list[tuple[FruitOutline, float]]:
    """The fruit in the ripe blobs ``every`` (of a mask of ``shape`` (H, W)), each once, with
    the degrees of its outline seen; longest outline first. ``rims``: interior arcs (edges
    inside the mask), each numbered by its blob in ``every``; they join a blob's arcs.
    ``stretch(at_px)``: the map under which a fruit near that pixel is a circle
    (:func:`~bve_mj.perception.instances.fruit_stretch`), taken at each blob's centre.

    Each blob of at least ``cfg.min_area_px``, largest first, is taken with its neighbouring
    fragments as ``detect`` takes the blob its prediction falls on, their arcs grouped into
    fruit, and the fruit with arcs of that blob kept; a blob whose every seeding arc is
    already in a measurable fruit kept is not taken again (its neighbourhood holds nothing
    new)."""
    H, W = shape[:2]
    arcs_of: dict[int, list[Arc]] = {}
    rims_of: dict[int, list[Arc]] = {}
    for a in rims:
        rims_of.setdefault(a.blob, []).append(a)

    def arcs(k: int) -> list[Arc]:
        if k not in arcs_of:  # the blob's arcs, numbered by its index in ``every``
            o = every[k].outline
            usable = (o[:, 0] > 0) & (o[:, 0] < W - 1) & (o[:, 1] > 0) & (o[:, 1] < H - 1)
            arcs_of[k] = outline_arcs(o + 0.5, usable, k, corner_px=cfg.corner_px, margin=cfg.junction_margin)
            arcs_of[k] += rims_of.get(k, [])
        return arcs_of[k]

    index = {id(b): k for k, b in enumerate(every)}
    big = sorted((k for k, b in enumerate(every) if b.area >= cfg.min_area_px), key=lambda k: -every[k].area)
    claimed: set[int] = set()  # ids of the arcs in a measurable fruit kept
    whole: list[tuple[FruitOutline, float]] = []
    part: list[tuple[FruitOutline, float]] = []
    for k in big:
        seeds = [a for a in arcs(k) if a.convex and len(a.points) >= _MIN_SEED]
        if not seeds or all(id(a) in claimed for a in seeds):
            continue
        near = [index[id(b)] for b in _nearby(every, every[k])]
        found = group_arcs(
            [a for j in near for a in arcs(j)],
            tol_px=cfg.arc_tol_px,
            shape_rel=shape_rel,
            stretch=None if stretch is None else stretch(every[k].centroid),
        )
        w, p = measurable_fruit(found, cfg.min_arc_deg)
        for fr, seen in w + p:
            if k in fr.blobs:
                if seen >= cfg.min_arc_deg:
                    whole.append((fr, seen))
                    claimed.update(id(a) for a in fr.arcs)
                else:
                    part.append((fr, seen))
    # a partial outline inside a measurable fruit's circle (found from another blob) is the
    # edge of a stem or calyx over it; a fruit found twice is measured once: the measurable
    # one, else the one with the longest outline
    part = [(fr, seen) for fr, seen in part if not any(_inside(fr, w.circle) for w, _ in whole)]
    kept: list[tuple[FruitOutline, float]] = []
    for fr, seen in sorted(whole, key=lambda e: -len(e[0].points)) + sorted(
        part, key=lambda e: -len(e[0].points)
    ):
        if not any(_same_fruit(fr, other) for other, _ in kept):
            kept.append((fr, seen))
    kept.sort(key=lambda e: -len(e[0].points))
    return kept


def _same_fruit(a: FruitOutline, b: FruitOutline) -> bool:
    """Whether two groups of arcs are one fruit seen twice: their circles' centres are less
    than half the larger radius apart."""
    apart = float(np.linalg.norm(a.circle.centre - b.circle.centre))
    return apart <= 0.5 * max(a.circle.radius, b.circle.radius)
