"""Procedural geometry of a high-wire tomato crop: stems, compound leaves, trusses, calyces.

Pure numpy: every function returns vertices and triangles (or points) in the world frame; the
scene (:mod:`bve_mj.sim.scene`) turns them into MuJoCo mesh geoms. Thin, many parts are
meshes made here from the numbers in docs/greenhouse.md rather than MuJoCo primitives,
because a primitive is drawn with ~900 triangles: a crop of ~1000 ellipsoid leaflets would
cost ~100 ms a frame in a software renderer, the same leaflets as meshes ~1 ms. Fruit stay
ellipsoid geoms (their silhouette is what the detector measures).

Fruit of a truss are placed touching: the centre distance at which two ellipsoids touch
along a direction d is min over normals n of (h_A(n) + h_B(n)) / (n . d), h the support
functions (h(n) = sqrt(n' S n) for an ellipsoid with shape matrix S), a convex problem in
two variables solved by Newton's method (:func:`contact_distance`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cache
from typing import NamedTuple

import numpy as np

__all__ = [
    "Leaflet",
    "MeshParts",
    "calyx",
    "contact_distance",
    "ellipsoid_shape",
    "leaflet_meshes",
    "rotation_zx",
    "smooth_path",
    "tube",
]


@dataclass
class MeshParts:
    """Vertices (n, 3) and triangles (m, 3) gathered from several parts into one mesh."""

    verts: list[np.ndarray] = field(default_factory=list)
    faces: list[np.ndarray] = field(default_factory=list)
    count: int = 0

    def add(self, verts: np.ndarray, faces: np.ndarray) -> None:
        self.verts.append(np.asarray(verts, dtype=float))
        self.faces.append(np.asarray(faces, dtype=int) + self.count)
        self.count += len(verts)

    def extend(self, other: tuple[np.ndarray, np.ndarray]) -> None:
        self.add(*other)

    @property
    def empty(self) -> bool:
        return self.count == 0

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        return np.concatenate(self.verts), np.concatenate(self.faces)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product of two 3-vectors (np.cross is slow for single vectors)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def rotation_zx(yaw: float, tilt: float) -> np.ndarray:
    """R = Rz(yaw) Rx(tilt): a fruit turned about its vertical axis, then tilted."""
    cz, sz, cx, sx = math.cos(yaw), math.sin(yaw), math.cos(tilt), math.sin(tilt)
    rz = np.array([[cz, -sz, 0.0], [sz, cz, 0.0], [0.0, 0.0, 1.0]])
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cx, -sx], [0.0, sx, cx]])
    return rz @ rx


def ellipsoid_shape(semi_axes: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Shape matrix S = R diag(a²) R': the ellipsoid is {x : x' S⁻¹ x <= 1}, h(n) = √(n' S n)."""
    return R @ np.diag(np.asarray(semi_axes, dtype=float) ** 2) @ R.T


def contact_distance(S_a: np.ndarray, S_b: np.ndarray, d: np.ndarray) -> tuple[float, float]:
    """Centre distance t at which ellipsoids A and B (shape matrices) touch with B's centre
    at A's + t d, and n·d for the contact normal n (a gap g needs t + g / (n·d))."""
    d = np.asarray(d, dtype=float) / np.linalg.norm(d)
    e1 = _cross(d, np.array([0.0, 0.0, 1.0]) if abs(d[2]) < 0.9 else np.array([1.0, 0.0, 0.0]))
    e1 /= np.linalg.norm(e1)
    e2 = _cross(d, e1)
    E = np.column_stack((e1, e2))
    ab = np.zeros(2)
    for _ in range(30):  # f(ab) = |S_a^½ v| + |S_b^½ v|, v = d + E ab: convex
        v = d + E @ ab
        grad = np.zeros(2)
        hess = np.zeros((2, 2))
        for S in (S_a, S_b):
            q = float(v @ S @ v)
            h = math.sqrt(q)
            g = E.T @ (S @ v) / h
            grad += g
            hess += (E.T @ S @ E) / h - np.outer(g, g) / h
        step = np.linalg.solve(hess + 1e-12 * np.eye(2), grad)
        ab -= step
        if np.linalg.norm(step) < 1e-12:
            break
    v = d + E @ ab
    t = math.sqrt(float(v @ S_a @ v)) + math.sqrt(float(v @ S_b @ v))
    return t, 1.0 / float(np.linalg.norm(v))


def smooth_path(points: np.ndarray, per_segment: int = 4) -> np.ndarray:
    """A Catmull-Rom curve through ``points`` (k, 3), ``per_segment`` samples per span."""
    p = np.asarray(points, dtype=float)
    if len(p) < 3:
        return p
    ext = np.vstack([2 * p[0] - p[1], p, 2 * p[-1] - p[-2]])
    out = [p[0]]
    for i in range(1, len(ext) - 2):
        p0, p1, p2, p3 = ext[i - 1], ext[i], ext[i + 1], ext[i + 2]
        for s in np.linspace(0.0, 1.0, per_segment + 1)[1:]:
            out.append(
                0.5
                * (
                    2 * p1
                    + (-p0 + p2) * s
                    + (2 * p0 - 5 * p1 + 4 * p2 - p3) * s**2
                    + (-p0 + 3 * p1 - 3 * p2 + p3) * s**3
                )
            )
    return np.array(out)


def tube(points: np.ndarray, radii: np.ndarray | float, sides: int = 6) -> tuple[np.ndarray, np.ndarray]:
    """A generalised cylinder along a polyline (k, 3), open ends, outward-facing triangles."""
    p = np.asarray(points, dtype=float)
    r = np.broadcast_to(np.asarray(radii, dtype=float), (len(p),))
    tangent = np.gradient(p, axis=0)
    tangent /= np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True), 1e-12)
    ref = np.array([0.0, 0.0, 1.0]) if abs(tangent[0, 2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    normal = _cross(tangent[0], ref)
    normal /= np.linalg.norm(normal)
    theta = np.arange(sides) * 2.0 * math.pi / sides
    cos_t, sin_t = np.cos(theta)[:, None], np.sin(theta)[:, None]
    rings = []
    for i in range(len(p)):  # parallel transport of the normal along the curve
        normal = normal - (normal @ tangent[i]) * tangent[i]
        normal /= np.linalg.norm(normal)
        binormal = _cross(tangent[i], normal)
        rings.append(p[i] + r[i] * (cos_t * normal + sin_t * binormal))
    return np.concatenate(rings), _tube_faces(len(p), sides)


@cache
def _tube_faces(rings: int, sides: int) -> np.ndarray:
    """The triangles joining ``rings`` rings of ``sides`` vertices (read-only, shared)."""
    faces = []
    for i in range(rings - 1):
        for j in range(sides):
            a, b = i * sides + j, i * sides + (j + 1) % sides
            c, d = b + sides, a + sides
            faces += [(a, b, c), (a, c, d)]
    out = np.array(faces)
    out.flags.writeable = False
    return out


class Leaflet(NamedTuple):
    """An ovate, serrated leaflet from ``base`` along ``axis``, its upper side towards ``up``
    (world frame), ``length`` and ``width`` [m], ``segments`` spans from base to tip; its mesh
    is made by :func:`leaflet_meshes`.

    ``fold``: angle [rad] the halves fall away from the midrib; ``droop``: the tip's drop as a
    share of the length; ``serration``: depth of the teeth as a share of the half-width.
    """

    base: np.ndarray
    axis: np.ndarray
    up: np.ndarray
    length: float
    width: float
    fold: float = 0.3
    droop: float = 0.15
    serration: float = 0.12
    segments: int = 10


_SIGN = np.array([0.0, 1.0, -1.0])[:, None]  # the midrib, the left (+v) and right edges


def leaflet_meshes(leaflets: Sequence[Leaflet]) -> list[tuple[np.ndarray, np.ndarray]]:
    """The two-sided meshes (vertices, triangles) of ``leaflets``, in order: those with the
    same number of segments computed together, each vertex by the same arithmetic as one
    leaflet alone (the same bits; a compound leaf's ~10 leaflets at the cost of ~2)."""
    frames = []
    for leaf in leaflets:  # each leaflet's frame: u along it, w its upper side, v to its left
        u = np.asarray(leaf.axis, dtype=float) / np.linalg.norm(leaf.axis)
        up = np.asarray(leaf.up, dtype=float)
        w = up - (up @ u) * u
        w /= np.linalg.norm(w)
        frames.append((u, _cross(w, u), w))
    out: list[tuple[np.ndarray, np.ndarray] | None] = [None] * len(leaflets)
    for segments in sorted({leaf.segments for leaf in leaflets}):
        idx = [i for i, leaf in enumerate(leaflets) if leaf.segments == segments]
        group = [leaflets[i] for i in idx]
        t, shape, teeth, t2 = _leaflet_profile(segments)
        length = np.array([leaf.length for leaf in group])
        width = np.array([leaf.width for leaf in group])
        half = (0.5 * width)[:, None] * shape
        half *= 1.0 - np.array([leaf.serration for leaf in group])[:, None] * teeth
        rib_drop = (-np.array([leaf.droop for leaf in group]) * length)[:, None] * t2
        along = (length[:, None] * t)[:, None, :] + (0.04 * length)[:, None, None] * (_SIGN != 0.0)
        lateral = _SIGN * half[:, None, :]
        tan_fold = np.array([math.tan(leaf.fold) for leaf in group])
        height = rib_drop[:, None, :] - (tan_fold[:, None] * half)[:, None, :] * np.abs(_SIGN)
        u, v, w = (np.array([frames[i][k] for i in idx])[:, None, None, :] for k in range(3))
        base = np.array([np.asarray(leaf.base, dtype=float) for leaf in group])[:, None, None, :]
        top = (base + along[..., None] * u + lateral[..., None] * v + height[..., None] * w).reshape(
            len(group), -1, 3
        )
        bottom = top - (0.0004 * w[:, 0])
        faces = _two_sided_faces(segments)
        for k, i in enumerate(idx):
            out[i] = (np.vstack([top[k], bottom[k]]), faces)
    return [m for m in out if m is not None]


@cache
def _leaflet_profile(segments: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Along a leaflet of ``segments`` spans: the stations t in [0, 1], the half-width's shape,
    the teeth (every other station) and t² (read-only, shared)."""
    t = np.linspace(0.0, 1.0, segments + 1)
    out = (t, np.sin(math.pi * t**0.75) ** 0.8, (np.arange(segments + 1) % 2).astype(float), t**2)
    for a in out:
        a.flags.writeable = False
    return out


@cache
def _two_sided_faces(segments: int) -> np.ndarray:
    """A leaflet's triangles, top and (reversed) bottom (read-only, shared)."""
    faces = _leaflet_faces(segments)
    out = np.vstack([faces, faces[:, ::-1] + 3 * (segments + 1)])
    out.flags.writeable = False
    return out


@cache
def _leaflet_faces(segments: int) -> np.ndarray:
    """The top triangles of a leaflet of ``segments`` spans (read-only, shared)."""
    n = segments + 1
    faces = []
    for k in range(segments):
        m0, m1, l0, l1, r0, r1 = k, k + 1, n + k, n + k + 1, 2 * n + k, 2 * n + k + 1
        faces += [(m0, m1, l1), (m0, l1, l0), (m0, r1, m1), (m0, r0, r1)]
    out = np.array(faces)
    out.flags.writeable = False
    return out


def calyx(
    top: np.ndarray,
    R: np.ndarray,
    semi_axes: np.ndarray,
    sepal_length: float,
    rng: np.random.Generator,
    segments: int = 5,
) -> tuple[np.ndarray, np.ndarray]:
    """A green star of 5-6 sepals lying on the fruit's shoulder, tips curling up.

    ``top``: the stem end of the fruit (world); ``R``, ``semi_axes``: the fruit's ellipsoid.
    """
    centre = top - R @ np.array([0.0, 0.0, semi_axes[2]])
    n_sepals = int(rng.integers(5, 7))
    parts = MeshParts()
    r_eq = float(semi_axes[0])
    theta_max = min(1.3, sepal_length / r_eq)
    for k in range(n_sepals):
        psi = 2.0 * math.pi * k / n_sepals + rng.uniform(-0.25, 0.25)
        length_k = rng.uniform(0.8, 1.1)
        t = np.linspace(0.0, 1.0, segments + 1)
        theta = theta_max * length_k * t
        local = np.stack(
            [
                semi_axes[0] * np.sin(theta) * math.cos(psi),
                semi_axes[1] * np.sin(theta) * math.sin(psi),
                semi_axes[2] * np.cos(theta),
            ],
            -1,
        )
        normal = local / semi_axes**2
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        lift = 0.0008 + 0.3 * sepal_length * t**3
        spine = local + lift[:, None] * normal
        side = np.array([-math.sin(psi), math.cos(psi), 0.0])
        half = 0.11 * sepal_length * np.sin(math.pi * np.clip(t, 0.05, 1.0) ** 0.6) + 0.0006
        left = spine + half[:, None] * side
        right = spine - half[:, None] * side
        verts_local = np.vstack([spine, left, right])
        m = segments + 1
        faces = []
        for i in range(segments):
            s0, s1, l0, l1, r0, r1 = i, i + 1, m + i, m + i + 1, 2 * m + i, 2 * m + i + 1
            faces += [(s0, s1, l1), (s0, l1, l0), (s0, r1, s1), (s0, r0, r1)]
        world = centre + verts_local @ R.T
        up = normal @ R.T
        top_v, top_f = world, np.array(faces)
        bottom = top_v - 0.0004 * np.vstack([up, up, up])
        parts.add(np.vstack([top_v, bottom]), np.vstack([top_f, top_f[:, ::-1] + len(top_v)]))
    return parts.arrays()
