"""Instance separation of the ripe mask: which outline points belong to which fruit.

The tomatoes of a truss touch, so one ripe blob is usually several fruit, and one fruit can
be several blobs (a stem across it, uneven colour). Each fruit's silhouette is an ellipse in
the image, and a circle once the fruit's mean shape is undone (where the world's vertical is
known, the points are scaled along its image by the fruit type's apparent elongation:
:func:`fruit_stretch`; a plum tomato is 1.2-1.6 times as tall as wide, and circles cut it in
two, one through each end); the outline of a union of overlapping circles turns inwards
wherever two of them meet. So:

1. every blob's outline is cut into arcs at its concave corners (recursively into the
   pockets between the outline and its convex hull), at its sharp corners (where the
   silhouette meets the straight edge of a stem or leaf across it) and where it runs along
   the image edge; the few points at each end of an arc that meets a corner are blended
   with the neighbour and left out (:mod:`bve_mj.perception.outline_cuts`);
2. arcs that bend inwards or run straight (the edge of a calyx, a stem, a leaf; the gap
   between fragments) are occluder edges, not silhouette: they are dropped;
3. the arcs are grouped into fruit: the arc that best fits its own circle seeds one, arcs
   lying on that circle join one at a time (the circle refitted after each), and an arc on
   no circle seeds its own; groups lying on one circle are merged, and so are two groups
   whose circles nearly coincide when the circle through both holds each and neither shows
   180° of its outline (the parts of an oval fruit cut by a stem, each part's own circle
   off by pixels; a part that shows more fixes its own circle). Arcs of one fruit on
   both sides of an occluder join; arcs of two touching fruit do not, whatever the
   overlap, because each lies on its own circle.

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

import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import cv2
import numpy as np

from bve_mj.perception.detection import Intrinsics
from bve_mj.perception.outline_cuts import Arc, _median, concave_corners, outline_arcs, sharp_corners

__all__ = [
    "Arc",
    "Circle",
    "FruitOutline",
    "concave_corners",
    "fit_circle",
    "fruit_stretch",
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


def fruit_stretch(
    intrinsics: Intrinsics, up_camera: np.ndarray | None, shape_index: float, at_px: np.ndarray
) -> np.ndarray | None:
    """The linear map (2, 2) of image points that turns the silhouette of a spheroid fruit of
    ``shape_index`` (height / width) hanging along ``up_camera`` (the world's vertical in
    the camera frame), seen near pixel ``at_px``, into a circle: its outline is an ellipse,
    its axis along the image of the vertical there and elongated by a = √(cos²φ + k² sin²φ)
    (φ between the line of sight and the axis), and the map scales it by 1/a along that
    direction (the equatorial radius unchanged). None where the vertical is not known or
    the fruit is seen end-on (the outline a circle anyway)."""
    if up_camera is None:
        return None
    up = np.asarray(up_camera, dtype=float)
    n_up = float(np.linalg.norm(up))
    if not (np.all(np.isfinite(up)) and n_up > 1e-9):
        return None
    up = up / n_up
    ray = intrinsics.rays(np.asarray(at_px, dtype=float))[0]
    d = intrinsics.project(ray + 1e-3 * up) - intrinsics.project(ray)
    n_d = float(np.linalg.norm(d))
    if not math.isfinite(n_d) or n_d < 1e-9:
        return None
    d /= n_d
    cos_phi = float(np.clip(abs(ray @ up), 0.0, 1.0))
    a = math.sqrt(cos_phi**2 + shape_index**2 * (1.0 - cos_phi**2))
    return np.eye(2) + (1.0 / a - 1.0) * np.outer(d, d)


def group_arcs(
    arcs: list[Arc],
    *,
    tol_px: float = 2.0,
    tol_rel: float = 0.04,
    shape_rel: float = 0.0,
    min_seed: int = 8,
    stretch: np.ndarray | None = None,
) -> list[FruitOutline]:
    """Group convex arcs into fruit.

    ``stretch``: a linear map (2, 2) of the points under which a fruit's outline is a circle
    (:func:`fruit_stretch`: an elongated or flattened fruit is an ellipse in the image, and
    the circle through one end of a plum tomato misses its sides, so circles alone cut it
    in two); the arcs are grouped in the mapped points, and each fruit's circle is given
    back in the image (its centre mapped back, its radius the equatorial one).

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
    if stretch is not None:
        M = np.asarray(stretch, dtype=float)
        mapped = [replace(a, points=a.points @ M.T) for a in arcs]
        found = group_arcs(mapped, tol_px=tol_px, tol_rel=tol_rel, shape_rel=shape_rel, min_seed=min_seed)
        original = {id(m): a for m, a in zip(mapped, arcs, strict=True)}
        inverse = np.linalg.inv(M)
        return [
            FruitOutline(
                Circle(inverse @ fr.circle.centre, fr.circle.radius), tuple(original[id(a)] for a in fr.arcs)
            )
            for fr in found
        ]
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
    groups = _join_split(groups, conv, tol, shape_rel)
    fruit = [FruitOutline(c, tuple(conv[m] for m in sorted(ms))) for c, ms in groups]
    fruit.sort(key=lambda fr: -len(fr.points))
    return fruit


_FIXED_DEG = 180  # a group showing this much of its outline fixes its own circle [deg]


def _join_split(
    groups: list[tuple[Circle, list[int]]], conv: list[Arc], tol: Callable[[Circle], float], shape_rel: float
) -> list[tuple[Circle, list[int]]]:
    """Join two groups that are one fruit split by an occluder across it (a stem, a
    peduncle): each holds a part of its outline, and the circle through a part is off (a
    fruit that is not a sphere is an ellipse; a short arc's circle is poorly fixed), so the
    other part lies off it and the merge above misses it. Two groups whose circles nearly
    coincide (centres within half the larger radius, radii within a quarter), each showing
    less than ``_FIXED_DEG`` of its outline, are one fruit when the circle through both holds
    each as a group's own circle would (half its points on it, almost none outside). A group
    that shows more fixes its own circle: an arc off it is another fruit's (one behind,
    peeping out) even where an oval could pass through both."""

    def short(ms: list[int], c: Circle) -> bool:
        pts = np.vstack([conv[m].points for m in ms])
        ang = np.arctan2(pts[:, 1] - c.centre[1], pts[:, 0] - c.centre[0])
        return 10 * len(np.unique(np.floor(np.degrees(ang) / 10.0))) < _FIXED_DEG

    joined = True
    while joined and len(groups) > 1:
        joined = False
        for i, j in itertools.combinations(range(len(groups)), 2):
            (ci, mi), (cj, mj) = groups[i], groups[j]
            big = max(ci.radius, cj.radius)
            if np.hypot(*(ci.centre - cj.centre)) > 0.5 * big or abs(ci.radius - cj.radius) > 0.25 * big:
                continue
            if not (short(mi, ci) and short(mj, cj)):
                continue
            parts = [np.vstack([conv[m].points for m in ms]) for ms in (mi, mj)]
            c = _robust_circle(np.vstack(parts))
            if c is None:
                continue
            sizes = np.array([len(p) for p in parts])
            arc_of = np.repeat([0, 1], sizes)  # the two groups' points, as two "arcs"
            on, out = _shares(np.vstack(parts), arc_of, sizes, c, tol(c), shape_rel * c.radius)
            if np.all(on >= 0.5 * sizes) and np.all(out <= 0.1 * sizes):
                groups = [g for k, g in enumerate(groups) if k not in (i, j)] + [(c, mi + mj)]
                joined = True
                break
    return groups


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
