"""Cutting a blob's outline into arcs: the first step of instance separation
(:mod:`bve_mj.perception.instances` groups the arcs into fruit).

Every blob's outline is cut at its concave corners (recursively into the pockets between the
outline and its convex hull: where two overlapping fruit meet), at its sharp corners (where
the silhouette meets the straight edge of a stem or leaf across it) and where it runs along
the image edge; the few points at each end of an arc that meets a corner are blended with
the neighbour and left out. Arcs that bend inwards or run straight are marked not convex:
occluder edges, not silhouette.

Pixel coordinates are those the outlines are given in (the detector passes pixel centres:
OpenCV's indices + 0.5).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

__all__ = ["Arc", "concave_corners", "outline_arcs", "sharp_corners"]


@dataclass(frozen=True, eq=False)
class Arc:
    """A stretch of a blob's outline between two corners (concave, or sharp where an occluder
    edge meets the silhouette) or the image edge.

    Attributes:
        points: (N, 2) in outline order [px].
        blob: which blob it bounds (the caller's number for it).
        convex: it bends outwards, as a silhouette does (an occluder edge bends inwards or
            runs straight).
        interior: it is not the blob's outline but an edge inside the ripe mask (a step in
            brightness where a fruit's rim lies over a ripe neighbour: red on red). Such an
            arc joins a fruit whose circle it lies on, and never seeds one (a cast shadow, a
            blush, a highlight's rim are edges inside a fruit too). Its points are the pixels
            where the brightness changes fastest, which lie about as far inside the true
            silhouette as an outline's boundary pixels (the limb darkens into the edge), so
            the fit treats both alike.
    """

    points: np.ndarray
    blob: int
    convex: bool
    interior: bool = False


def _median(x: np.ndarray) -> float:
    """The (upper) median, by partition: much cheaper than np.median on short arrays."""
    k = len(x) // 2
    return float(np.partition(x, k)[k])


def _orientation(outline: np.ndarray) -> float:
    """+1 or -1: the sign that makes depths into the interior positive (shoelace area)."""
    x, y = outline[:, 0], outline[:, 1]
    return 1.0 if float(x @ np.roll(y, -1) - np.roll(x, -1) @ y) > 0.0 else -1.0


def _depth(points: np.ndarray, a: np.ndarray, b: np.ndarray, inward: float) -> np.ndarray:
    """Signed distance of points from the chord a→b, positive into the shape's interior."""
    chord = b - a
    length = float(np.linalg.norm(chord))
    if length < 1e-9:
        return np.zeros(len(points))
    rel = points - a
    return inward * (rel[:, 1] * chord[0] - rel[:, 0] * chord[1]) / length


def concave_corners(outline: np.ndarray, depth_px: float) -> np.ndarray:
    """Indices of the concave corners of a closed outline (N, 2), sorted: the deepest point
    of every pocket between the outline and its convex hull deeper than ``depth_px``, and
    recursively of the two halves it leaves (a pocket can hold two corners: a junction of
    two fruit beside a calyx notch)."""
    n = len(outline)
    if n < 8:
        return np.zeros(0, dtype=int)
    hull = np.sort(cv2.convexHull(outline.astype(np.float32), returnPoints=False).reshape(-1))
    inward = _orientation(outline)
    found: list[int] = []
    # every point's depth below the hull edge spanning it, at once: only the pockets deeper
    # than the threshold are searched (the rest are the staircase of the pixel grid)
    edge = (np.searchsorted(hull, np.arange(n), side="right") - 1) % len(hull)
    a_pt, b_pt = outline[hull[edge]], outline[hull[(edge + 1) % len(hull)]]
    chord = b_pt - a_pt
    rel = outline - a_pt
    length = np.maximum(np.hypot(chord[:, 0], chord[:, 1]), 1e-9)
    depth = inward * (rel[:, 1] * chord[:, 0] - rel[:, 0] * chord[:, 1]) / length
    deep = np.unique(edge[depth > depth_px])
    stack = [(int(hull[e]), int(hull[(e + 1) % len(hull)])) for e in deep]
    while stack:
        a, b = stack.pop()
        span = (b - a) % n
        if span < 3:
            continue
        idx = (a + np.arange(1, span)) % n
        depth = _depth(outline[idx], outline[a], outline[b], inward)
        j = int(np.argmax(depth))
        if depth[j] <= depth_px:
            continue
        c = int(idx[j])
        found.append(c)
        stack.extend(((a, c), (c, b)))
    return np.array(sorted(set(found)), dtype=int)


def sharp_corners(outline: np.ndarray, step: int = 5, angle_deg: float = 40.0) -> np.ndarray:
    """Indices of the sharp corners of a closed outline (N, 2), sorted: where the direction
    over ``step`` points turns by more than ``angle_deg`` (a local maximum of the turn). A
    silhouette is smooth; it meets the straight edge of a stem or leaf across it at a corner,
    convex or concave."""
    n = len(outline)
    if n < 4 * step:
        return np.zeros(0, dtype=int)
    before = outline - np.roll(outline, step, axis=0)
    after = np.roll(outline, -step, axis=0) - outline
    cross = before[:, 0] * after[:, 1] - before[:, 1] * after[:, 0]
    turn = np.abs(np.arctan2(cross, (before * after).sum(axis=1)))
    peak = turn >= np.radians(angle_deg)
    for s in range(1, step + 1):
        peak &= (turn >= np.roll(turn, s)) & (turn > np.roll(turn, -s))
    return np.flatnonzero(peak)


def outline_arcs(
    outline: np.ndarray,
    usable: np.ndarray,
    blob: int,
    *,
    corner_px: float = 1.5,
    margin: int = 4,
    min_points: int = 6,
) -> list[Arc]:
    """Cut a closed outline (N, 2) into arcs at its concave and sharp corners and its unusable
    points (the image edge), dropping ``margin`` points at each end of an arc that meets a
    corner.

    Args:
        usable: (N,) bool, False where the outline runs along the image edge.
        blob: the blob's number, carried by its arcs.
        corner_px: concave corners deeper than this cut the outline [px].
        margin: points left out at an arc's end beside a corner (blended with the neighbour).
        min_points: shorter arcs are dropped.
    """
    n = len(outline)
    if n == 0:
        return []
    corner = np.zeros(n, dtype=bool)
    corner[concave_corners(outline, corner_px)] = True
    corner[sharp_corners(outline)] = True
    cut = corner | ~usable
    if not cut.any():  # no corner: the whole outline is one (closed) arc
        return [Arc(outline, blob, True)] if n >= min_points else []
    inward = _orientation(outline)
    order = np.roll(np.arange(n), -int(np.argmax(cut)))  # start at a cut: no run wraps
    inside = (~cut[order]).astype(np.int8)
    starts = np.flatnonzero(np.diff(inside) == 1) + 1
    ends = np.flatnonzero(np.diff(np.append(inside, 0)) == -1) + 1
    arcs = []
    for lo, hi in zip(starts, ends, strict=True):
        lo += margin if corner[order[lo - 1]] else 0
        hi -= margin if corner[order[hi % n]] else 0
        if hi - lo < min_points:
            continue
        pts = outline[order[lo:hi]]
        # a silhouette arc bends outwards: its points lie outside its chord, by a sagitta a
        # long arc cannot lack; a long straight stretch is the edge of a stem or leaf
        depth = _depth(pts, pts[0], pts[-1], inward)
        chord = float(np.linalg.norm(pts[-1] - pts[0]))
        convex = _median(depth) <= 0.5 and (chord < 24.0 or -float(depth.min()) >= 1.0)
        arcs.append(Arc(pts, blob, convex))
    return arcs
