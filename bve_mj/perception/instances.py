"""Instance separation of the ripe mask: which outline points belong to which fruit.

The tomatoes of a truss touch, so one ripe blob is usually several fruit, and one fruit can
be several blobs (a stem across it, uneven colour). Each fruit's silhouette is a circle in
the image (an ellipse off-axis, close enough to group points by), and the outline of a
union of overlapping circles turns inwards wherever two of them meet. So:

1. every blob's outline is cut into arcs at its concave corners (recursively into the
   pockets between the outline and its convex hull), at its sharp corners (where the
   silhouette meets the straight edge of a stem or leaf across it) and where it runs along
   the image edge; the few points at each end of an arc that meets a corner are blended
   with the neighbour and left out;
2. arcs that bend inwards or run straight (the edge of a calyx, a stem, a leaf; the gap
   between fragments) are occluder edges, not silhouette: they are dropped;
3. the arcs are grouped into fruit: the arc that best fits its own circle seeds one, arcs
   lying on that circle join one at a time (the circle refitted after each), and an arc on
   no circle seeds its own; groups lying on one circle are merged. Arcs of one fruit on both
   sides of an occluder join; arcs of two touching fruit do not, whatever the overlap,
   because each lies on its own circle.

Where two fruit meet there is no outline at all (red on red): the mask runs on over the
junction. But the nearer fruit's rim is still an edge of brightness there (its limb darkens
towards the edge, against the lit face of the fruit behind): those edges inside the mask
(:mod:`bve_mj.perception.rims`) become arcs too, which
join the fruit whose circle they lie on and never seed one. The fruit behind has no outline
there at all and is fitted on its own outer arcs.

Pixel coordinates here are those the outlines are given in (the detector passes pixel
centres: OpenCV's indices + 0.5).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

__all__ = [
    "Arc",
    "Circle",
    "FruitOutline",
    "concave_corners",
    "fit_circle",
    "group_arcs",
    "hull_points",
    "outline_arcs",
    "sharp_corners",
]


@dataclass(frozen=True)
class Circle:
    """An image circle [px]: centre (x, y) and radius."""

    centre: np.ndarray
    radius: float


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


@dataclass(frozen=True)
class FruitOutline:
    """One fruit: its circle and the arcs of outline that lie on it."""

    circle: Circle
    arcs: tuple[Arc, ...]

    @property
    def points(self) -> np.ndarray:
        return np.vstack([a.points for a in self.arcs])

    @property
    def blobs(self) -> frozenset[int]:
        return frozenset(a.blob for a in self.arcs)


def fit_circle(points: np.ndarray) -> Circle | None:
    """Algebraic (Kåsa) least-squares circle through points (N, 2); None if degenerate."""
    if len(points) < 3:
        return None
    mean = points.mean(axis=0)
    p = points - mean
    A = np.column_stack((2.0 * p, np.ones(len(p))))
    try:  # the normal equations of a 3-parameter fit: well conditioned once centred
        sol = np.linalg.solve(A.T @ A, A.T @ (p * p).sum(axis=1))
    except np.linalg.LinAlgError:
        return None
    r2 = sol[2] + sol[0] ** 2 + sol[1] ** 2
    if not np.isfinite(r2) or r2 <= 0.0:
        return None
    return Circle(sol[:2] + mean, float(np.sqrt(r2)))


def _median(x: np.ndarray) -> float:
    """The (upper) median, by partition: much cheaper than np.median on short arrays."""
    k = len(x) // 2
    return float(np.partition(x, k)[k])


def _robust_circle(points: np.ndarray, passes: int = 6) -> Circle | None:
    """A circle fit that drops points well inside it (occluder edges: a calyx, a leaf), at a
    threshold that tightens to 3 robust σ of the points kept (never below 1 px), and points
    far outside it (a neighbour's outline beyond a junction no corner marked)."""
    circle = fit_circle(points)
    keep = np.ones(len(points), dtype=bool)
    for _ in range(passes):
        if circle is None:
            return None
        resid = np.hypot(points[:, 0] - circle.centre[0], points[:, 1] - circle.centre[1]) - circle.radius
        kept = resid[keep]
        sigma = 1.4826 * _median(np.abs(kept - _median(kept)))
        new_keep = (resid > -max(1.0, 3.0 * sigma)) & (resid < max(3.0, 4.0 * sigma))
        if new_keep.sum() < 8 or np.array_equal(new_keep, keep):
            break
        keep = new_keep
        circle = fit_circle(points[keep])
    return circle


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


def _shares(
    points: np.ndarray, arc_of: np.ndarray, sizes: np.ndarray, circle: Circle, tol: float, inside: float
) -> tuple[np.ndarray, np.ndarray]:
    """Per arc: how many of its points lie on a circle (within ``tol`` outside it, ``tol +
    inside`` inside it), and how many lie more than ``2 tol`` outside it. ``points`` (N, 2)
    are all arcs' points, ``arc_of`` (N,) the arc of each, ``sizes`` the arcs' lengths."""
    resid = np.hypot(points[:, 0] - circle.centre[0], points[:, 1] - circle.centre[1]) - circle.radius
    on = np.bincount(arc_of, weights=(resid <= tol) & (resid >= -(tol + inside)), minlength=len(sizes))
    out = np.bincount(arc_of, weights=resid > 2.0 * tol, minlength=len(sizes))
    return on, out


def group_arcs(
    arcs: list[Arc],
    *,
    tol_px: float = 2.0,
    tol_rel: float = 0.04,
    shape_rel: float = 0.0,
    min_seed: int = 8,
) -> list[FruitOutline]:
    """Group convex arcs into fruit.

    The arc with the most points on its own circle seeds a fruit; arcs that lie on the
    fruit's circle (half their points or more within ``tol = max(tol_px, tol_rel·R)`` of it,
    or as far as ``tol + shape_rel·R`` inside it: a fruit that is not a sphere is an ellipse
    in the image, inside the circle through its widest parts; and almost none further
    outside: points inside may also be hidden) join one at a time, the best lying
    first, the circle refitted after each, until none does; the next free arc seeds the next
    fruit. Then a fruit whose points lie on another's circle in the same sense is merged
    into it: a seed spoilt by an occluder edge, or the edge of a calyx along the silhouette,
    can leave one fruit as two groups.

    Returns the fruit found, longest outline first."""
    # seeds in order of the points that lie on their own circle: a long arc that is half
    # an occluder's edge makes a poor seed
    scored: list[tuple[int, Arc, Circle | None]] = []
    for arc in arcs:
        if not arc.convex:
            continue
        own = _robust_circle(arc.points) if len(arc.points) >= min_seed else None
        fitting = 0
        if own is not None:
            r = np.hypot(arc.points[:, 0] - own.centre[0], arc.points[:, 1] - own.centre[1]) - own.radius
            fitting = int(np.count_nonzero(np.abs(r) <= max(tol_px, tol_rel * own.radius)))
        scored.append((fitting, arc, own))
    if not scored:
        return []
    scored.sort(key=lambda e: -e[0])
    conv = [arc for _, arc, _ in scored]
    sizes = np.array([len(arc.points) for arc in conv])
    points = np.vstack([arc.points for arc in conv])
    arc_of = np.repeat(np.arange(len(conv)), sizes)

    def tol(c: Circle) -> float:
        return max(tol_px, tol_rel * c.radius)

    def refit(members: list[int], fallback: Circle) -> Circle:
        c = _robust_circle(np.vstack([conv[m].points for m in members]))
        return fallback if c is None else c

    free = np.ones(len(conv), dtype=bool)
    groups: list[tuple[Circle, list[int]]] = []
    for seed, (_, arc, own) in enumerate(scored):
        if not free[seed] or sizes[seed] < min_seed or arc.interior:
            continue
        free[seed] = False
        if own is None:
            continue
        circle, members = own, [seed]
        while True:  # grow one arc at a time, the best lying first, refitting after each
            on, out = _shares(points, arc_of, sizes, circle, tol(circle), shape_rel * circle.radius)
            ok = (on >= 0.5 * sizes) & (out <= 0.1 * sizes) & free
            if not ok.any():
                break
            best = int(np.argmax(np.where(ok, on / sizes, -1.0)))
            free[best] = False
            members.append(best)
            circle = refit(members, circle)
        groups.append((circle, members))
    merged = True
    while merged and len(groups) > 1:
        merged = False
        group_of = np.full(len(conv), len(groups))  # arcs in no group: a dummy last group
        for g, (_, mg) in enumerate(groups):
            group_of[mg] = g
        group_size = np.bincount(group_of, weights=sizes, minlength=len(groups) + 1)[:-1]
        for i, (ci, mi) in enumerate(groups):
            on, out = _shares(points, arc_of, sizes, ci, tol(ci), shape_rel * ci.radius)
            on_g = np.bincount(group_of, weights=on, minlength=len(groups) + 1)[:-1]
            out_g = np.bincount(group_of, weights=out, minlength=len(groups) + 1)[:-1]
            lying = (on_g >= 0.5 * group_size) & (out_g <= 0.1 * group_size)
            lying[i] = False
            if lying.any():
                j = int(np.argmax(lying))
                members = mi + groups[j][1]
                groups = [g for k, g in enumerate(groups) if k not in (i, j)]
                groups.append((refit(members, ci), members))
                merged = True
                break
    fruit = [FruitOutline(c, tuple(conv[m] for m in sorted(ms))) for c, ms in groups]
    fruit.sort(key=lambda fr: -len(fr.points))
    return fruit


def hull_points(points: np.ndarray, tol_px: float = 1.0) -> np.ndarray:
    """Which points (N, 2) lie on the convex hull of them all (within ``tol_px``): the
    candidates for a convex silhouette; points in concavities (a leaf tip, the gaps between
    fragments of a fruit) are not. Boolean (N,)."""
    if len(points) < 4:
        return np.ones(len(points), dtype=bool)
    hull = cv2.convexHull(points.astype(np.float32)).reshape(-1, 2).astype(float)
    if len(hull) < 3:
        return np.ones(len(points), dtype=bool)
    edges = np.roll(hull, -1, axis=0) - hull
    normals = np.column_stack((edges[:, 1], -edges[:, 0]))
    norms = np.linalg.norm(normals, axis=1)
    ok = norms > 1e-9
    normals, hull = normals[ok] / norms[ok, None], hull[ok]
    # orient outward: the centroid is inside
    inside = points.mean(axis=0)
    sign = np.sign(((inside - hull) * normals).sum(axis=1))
    normals = normals * -np.where(sign == 0, 1.0, sign)[:, None]
    # distance inside the hull = min over edges of the distance to the edge's line
    depth = ((hull[None, :, :] - points[:, None, :]) * normals[None, :, :]).sum(axis=2).min(axis=1)
    return depth <= tol_px
