"""Which parts of the work zone the views have framed, and where to look for the rest.

An every-fruit episode may say it found every ripe fruit of the work zone (a ball of
``tracking.zone_m`` around the target's prior estimate) only if every part of that zone has
been in an image: a fruit outside every image is one the detector never had a chance to see.
The views the tracks ask for frame the fruit found, and a truss or plant wider than one image
(``plant_trusses``: a zone of 0.3 m, an image 0.26 m high at 0.25 m) keeps parts of the zone
out of every view: 3 of 16 such episodes of one seed said ``converged`` with a ripe fruit of
the second truss never in view.

The zone is sampled on a cubic grid (:data:`GRID_STEPS` points across its radius); a point
counts as framed by a view when it lies in front of the camera within the detector's range
and projects at least half a prior fruit's apparent radius inside the image border (a fruit
centred there shows two thirds of its outline or more in the image); with the detector's
``min_arc_deg``, a point counts as framed only once the views would have measured a fruit
there as surely as one clear view does, from the outline each shows of it past the fruit the
robot knows and the share of such views the detector measures (:data:`DETECTED_BY_ARC`):
the space behind the fruit in front is space no view has seen (``truss_cluster`` 428971644:
every view from the aisle, below the truss; the zone counted framed, the episode said
``converged`` with the two ripe fruit behind the front row never detected). That check is
``tracking.zone_behind_fruit``, off by default: it asks it only where a neighbour of a known
fruit would sit, and even so most episodes whose views all come from one side of the truss
end ``incomplete`` (``ripe_truss``, seed 3131: 1 of 20 ``converged``, 15 without it).
Occlusion by leaves, stems and fruit not tracked is not counted: that is what
``tracking.explore_span_deg`` (views from several directions) is for.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from bve_mj.estimation.visibility import arc_past_discs, image_discs
from bve_mj.geometry import camera_rotation, project_points

__all__ = ["DETECTED_BY_ARC", "GRID_STEPS", "ZoneCoverage", "detected_share", "outline_past", "zone_grid"]

GRID_STEPS = 4
"""Grid points per zone radius: a spacing of a quarter of ``zone_m`` (37.5 mm for 0.15 m, about
a tomato's diameter), 257 points in the ball."""

_MARGIN_SHARE = 0.5  # of a prior fruit's apparent radius, inside the image border


OCCUPIED_SHARE = 0.5
"""A fruit centred closer to a known fruit's surface than this share of its radius would sink
into it by more than half its radius: no fruit can be there (touching neighbours sit one
radius off), and the point is the known fruit's, not hidden by it."""


NEIGHBOUR_GAP_SHARE = 2.0
"""A fruit centred closer to a known fruit's surface than this share of its radius would touch
it or sit within a radius of touching: a neighbour in its truss (tomatoes of a truss touch),
where a fruit hidden behind the known ones would be. Only there must the views have shown a
fruit's outline past the known fruit (:meth:`ZoneCoverage.note`); farther off, in the
canopy behind the truss that no view from the aisle sees past, an image framing the point is
enough."""

DETECTED_BY_ARC = (
    (150.0, 0.33), (180.0, 0.51), (210.0, 0.50), (240.0, 0.66),
    (270.0, 0.75), (300.0, 0.79), (330.0, 0.85), (360.0, 0.85),
)  # fmt: skip
"""(outline shown from [deg], share of such views that measured the fruit), from
``python benchmarks/detection_by_arc.py`` (the every-fruit detector in 8 episodes each of
``truss_cluster``, ``ripe_truss`` and ``cherry_truss``, seed 7070: 1,534 views of a ripe fruit,
the outline each shows past every other fruit of the scene, spheres:
:func:`~bve_mj.estimation.visibility.visible_arc_deg`). Below ``min_arc_deg`` none (the
detector refuses it); a whole outline is measured 85% of the time, one of 150-180° a third of
it: a red fruit's edge on a red neighbour, a calyx or a stem over the rim leave the detector
less than the spheres do."""


def detected_share(arc_deg: np.ndarray, min_arc_deg: float) -> np.ndarray:
    """The share of views showing ``arc_deg`` of a fruit's outline that measure it
    (:data:`DETECTED_BY_ARC`; 0 below ``min_arc_deg``)."""
    a = np.asarray(arc_deg, dtype=float)
    edges = np.array([e for e, _ in DETECTED_BY_ARC])
    shares = np.array([0.0] + [q for _, q in DETECTED_BY_ARC])
    out = shares[np.searchsorted(edges, np.minimum(a, 360.0), side="right")]
    return np.where(a >= min_arc_deg, out, 0.0)


def outline_past(
    points_m: np.ndarray,
    fruit_radius_m: float,
    p_world_camera: np.ndarray,
    R_world_camera: np.ndarray,
    centres_m: np.ndarray,
    radii_m: np.ndarray,
    focal_px: float,
    width_px: int,
    height_px: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For a fruit of ``fruit_radius_m`` at each of ``points_m`` (n, 3): the degrees of its
    outline in the image and outside the image discs of the known fruit (``centres_m``/
    ``radii_m``, (k, 3)/(k,) [m]; :func:`~bve_mj.estimation.visibility.visible_arc_deg`, each
    point against the known fruit alone), (n,); and whether it would sink into a known one
    (:data:`OCCUPIED_SHARE`): no fruit can be there, the known one holds the point, (n,); and
    whether it would be a known one's neighbour in the truss (:data:`NEIGHBOUR_GAP_SHARE`),
    (n,)."""
    pts = np.atleast_2d(np.asarray(points_m, dtype=float))
    c = np.asarray(centres_m, dtype=float).reshape(-1, 3)
    r = np.asarray(radii_m, dtype=float).reshape(-1)
    n = len(pts)
    cam = (p_world_camera, R_world_camera, focal_px, width_px, height_px)
    uv, rad, front = image_discs(pts, np.full(n, fruit_radius_m), *cam)
    kuv, krad, _ = image_discs(c, r, *cam) if len(c) else (np.zeros((0, 2)), np.zeros(0), None)
    arc = np.where(front, arc_past_discs(uv, rad, kuv, krad, width_px, height_px), 0.0)
    gap = np.linalg.norm(pts[:, None, :] - c[None, :, :], axis=2) - r[None, :]  # (n, k)
    occupied = np.any(gap < OCCUPIED_SHARE * fruit_radius_m, axis=1)
    near = np.any(gap < NEIGHBOUR_GAP_SHARE * fruit_radius_m, axis=1)
    return arc, occupied, near


def zone_grid(centre_m: np.ndarray, radius_m: float, steps: int = GRID_STEPS) -> np.ndarray:
    """The points of a cubic grid (spacing ``radius_m / steps``, one point at the centre) that
    lie in the ball of ``radius_m`` around ``centre_m`` [m], (n, 3)."""
    if not (math.isfinite(radius_m) and radius_m > 0.0) or steps < 1:
        raise ValueError(f"a zone needs a radius > 0 and steps >= 1, got {radius_m!r}, {steps!r}")
    k = np.arange(-steps, steps + 1)
    g = np.stack(np.meshgrid(k, k, k, indexing="ij"), axis=-1).reshape(-1, 3)
    g = g[np.sum(g * g, axis=1) <= steps * steps]
    return np.asarray(centre_m, dtype=float) + g * (radius_m / steps)


@dataclass
class ZoneCoverage:
    """The work zone's grid points and which of them a view has framed.

    Args:
        centre_m: the zone's centre [m], (3,).
        radius_m: the zone's radius [m].
        fruit_radius_m: a prior fruit's radius [m] (sets the margin inside the image border).
        focal_px, width_px, height_px: the camera.
        max_range_m: points farther from the camera than this are not framed (the detector
            ignores fruit there).
        standoff_m: the distance a view keeps from what it looks at (the BVE's distance
            band), for :meth:`aim_m`; None: aim at the largest unframed patch.
        min_arc_deg: the outline the detector needs [deg]: a point where a fruit would show
            less past the known fruit (:meth:`note`'s ``blockers``) is not framed; 0: any
            point in the image is.
    """

    centre_m: np.ndarray
    radius_m: float
    fruit_radius_m: float
    focal_px: float
    width_px: int
    height_px: int
    max_range_m: float
    standoff_m: float | None = None  # the distance exploring views keep from their aim [m]
    min_arc_deg: float = 0.0  # the outline the detector needs; 0: points behind fruit count framed
    points_m: np.ndarray = field(init=False)
    framed: np.ndarray = field(init=False)
    _poses: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = field(init=False, repr=False)
    _counts_from: np.ndarray = field(init=False, repr=False)  # per point: the first view that counts
    _blockers: tuple[np.ndarray, np.ndarray] | None = field(init=False, repr=False)
    given_up: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        self.centre_m = np.asarray(self.centre_m, dtype=float).reshape(3)
        self.points_m = zone_grid(self.centre_m, self.radius_m)
        self.framed = np.zeros(len(self.points_m), dtype=bool)
        self._poses = []
        self._counts_from = np.zeros(len(self.points_m), dtype=int)
        self._blockers = None
        self.given_up = np.zeros(len(self.points_m), dtype=bool)

    def in_image(self, p_world_camera: np.ndarray, R_world_camera: np.ndarray) -> np.ndarray:
        """(n,) bool: the grid points a camera at ``p_world_camera`` with axes
        ``R_world_camera`` (columns: x optical axis, y left, z up) frames."""
        p, R = np.asarray(p_world_camera, dtype=float), np.asarray(R_world_camera, dtype=float)
        t = (self.points_m - p) @ R  # camera frame
        rho = np.linalg.norm(t, axis=1)
        front = (t[:, 0] > self.fruit_radius_m) & (rho <= self.max_range_m)
        depth = np.where(front, t[:, 0], 1.0)
        u, v = project_points(
            np.column_stack([depth, t[:, 1:]]), self.focal_px, self.width_px, self.height_px
        ).T
        margin = _MARGIN_SHARE * self.focal_px * self.fruit_radius_m / depth
        inside_u = (u >= margin) & (u <= self.width_px - margin)
        inside_v = (v >= margin) & (v <= self.height_px - margin)
        return front & inside_u & inside_v

    def note(
        self,
        p_world_camera: np.ndarray,
        R_world_camera: np.ndarray,
        blockers: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> None:
        """A view was taken from this pose: the points it framed count as seen.

        With a ``min_arc_deg``, a point counts as framed once the views would have measured a
        fruit there as surely as one clear view does: 1 - Π(1 - q_i) ≥ q(360°), q_i the share
        of views showing what view i would show of its outline past the known fruit
        (``blockers``: the fruit known now, centres (k, 3) [m] and radii (k,) [m]) that
        measure the fruit (:func:`detected_share`). Every view is counted again past the
        fruit known now (a fruit found later hides what the views before it could not have
        seen either). A point a known fruit holds, or that is no known fruit's neighbour in
        its truss (:func:`outline_past`), counts framed once in an image."""
        p = np.asarray(p_world_camera, dtype=float).copy()
        R = np.asarray(R_world_camera, dtype=float).copy()
        self._poses.append((p, R, self.in_image(p, R)))
        if blockers is not None:
            self._blockers = (
                np.asarray(blockers[0], dtype=float).reshape(-1, 3),
                np.asarray(blockers[1], dtype=float).reshape(-1),
            )
        counted = [(k >= self._counts_from) & in_image for k, (_, _, in_image) in enumerate(self._poses)]
        if self.min_arc_deg <= 0.0:
            self.framed = np.any(counted, axis=0)
            return
        known = self._blockers if self._blockers is not None else (np.zeros((0, 3)), np.zeros(0))
        clear = float(detected_share(np.array([360.0]), self.min_arc_deg)[0])
        missed = np.ones(len(self.points_m))
        held = np.zeros(len(self.points_m), dtype=bool)
        for (q, Rq, _), seen in zip(self._poses, counted, strict=True):
            arc, occupied, near = outline_past(
                self.points_m, self.fruit_radius_m, q, Rq, known[0], known[1],
                self.focal_px, self.width_px, self.height_px,
            )  # fmt: skip
            missed *= np.where(seen, 1.0 - detected_share(arc, self.min_arc_deg), 1.0)
            held |= seen & (occupied | ~near)
        self.framed = held | (1.0 - missed >= clear - 1e-9)

    @property
    def share(self) -> float:
        """The share of the zone's grid points framed by some view so far."""
        return float(np.mean(self.framed))

    @property
    def complete(self) -> bool:
        return bool(np.all(self.framed))

    @property
    def can_aim(self) -> bool:
        """Whether some unframed point is left to aim at (not given up)."""
        return bool(np.any(~self.framed & ~self.given_up))

    def look_again_near(self, points_m: np.ndarray, distance_m: float) -> None:
        """The grid points within ``distance_m`` of some point of ``points_m`` (k, 3) are to be
        framed again (not given up); the rest keep their state (a survey after a harvest: the
        zone changed only where fruit were picked, :mod:`bve_mj.loop.picking`)."""
        pts = np.asarray(points_m, dtype=float).reshape(-1, 3)
        if not (math.isfinite(distance_m) and distance_m > 0.0) or not np.all(np.isfinite(pts)):
            raise ValueError(f"look_again_near needs finite points and a distance > 0, got {distance_m!r}")
        d = np.linalg.norm(self.points_m[:, None, :] - pts[None, :, :], axis=2).min(axis=1, initial=np.inf)
        near = d <= distance_m
        self.framed &= ~near
        self._counts_from[near] = len(self._poses)  # the views before do not count for them
        self.given_up &= ~near

    def give_up(self, aim_m: np.ndarray) -> None:
        """A view aimed at ``aim_m`` framed nothing new (the arm cannot frame it within its
        constraints): the unframed points within half the zone's radius of it are not aimed at
        again. They stay unframed: the episode cannot say it saw the whole zone."""
        d = np.linalg.norm(self.points_m - np.asarray(aim_m, dtype=float), axis=1)
        self.given_up |= ~self.framed & (d <= 0.5 * self.radius_m)

    def aim_m(self, p_world_camera: np.ndarray | None = None) -> np.ndarray:
        """Where to look next for the zone's unframed part [m], (3,), among the unframed grid
        points not given up (the zone's centre when none is left).

        With the camera's position and a ``standoff_m``: the point whose view frames most of
        the unframed zone, that view taken from ``standoff_m`` away on the side the camera is
        now (as the BVE, held to its distance band, will look at it). On seed 4343's
        ``plant_trusses`` (a zone of 0.3 m) this framed the zone in a median of 13 views
        instead of 16, and 14 of 20 episodes ended ``converged`` instead of 7. Without them:
        the point with the most unframed points within half the zone's radius (the middle of
        the largest unframed patch)."""
        rest = self.points_m[~self.framed & ~self.given_up]
        if len(rest) == 0:
            return self.centre_m.copy()
        if p_world_camera is not None and self.standoff_m is not None:
            p = np.asarray(p_world_camera, dtype=float)
            best, gain = rest[0], -1
            for a in rest:
                d = p - a
                n = float(np.linalg.norm(d))
                if n <= 0.0:
                    continue
                cam = a + self.standoff_m * d / n
                new = int(np.count_nonzero(self.in_image(cam, camera_rotation(cam, a)) & ~self.framed))
                if new > gain:
                    best, gain = a, new
            return best.copy()
        d2 = np.sum((rest[:, None, :] - rest[None, :, :]) ** 2, axis=2)
        near = np.sum(d2 <= (0.5 * self.radius_m) ** 2, axis=1)
        return rest[int(np.argmax(near))].copy()
