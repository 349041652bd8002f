"""Fruit seen only in part: the evidence of a ripe fruit the detector could not measure.

A fruit behind its neighbours shows a short stretch of outline: the detector finds it (its
arcs group into a fruit) but refuses to measure it (too little outline, or arcs that pin
its centre down too loosely: :attr:`~bve_mj.perception.detection.NoDetection.partial`). Such
a refusal is not a measurement of the fruit, but it is evidence that one is there. Each is
turned into a weak sighting (:func:`unmeasured_sighting`): the bearing of the centre of the
circle its arcs lie on, and its apparent radius, with a noise measured against the truth
(the constants below). A second :class:`~bve_mj.estimation.tracks.Tracker` associates them
across views as it does detections: a fruit seen in part from :data:`CONFIRM_VIEWS` views at
one place in 3-D is confirmed (:func:`tracking_config`), a stem crossing seen once is not.

A confirmed one that no measured track explains (:func:`unexplained`) is a ripe fruit the
episode saw but did not localise: the every-fruit loop then does not say it found every
fruit (``incomplete``, not ``converged``), and reports where it is.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np

from bve_mj.config import TrackingConfig
from bve_mj.estimation.assignment import Sighting, image_offset
from bve_mj.estimation.ekf import nis_threshold
from bve_mj.estimation.models import BearingSizeModel
from bve_mj.estimation.tracks import Track

__all__ = [
    "CENTRE_SIGMA_REL",
    "CONFIRM_VIEWS",
    "EXPLAINED_PROBABILITY",
    "IN_VIEW_SHARE",
    "NO_NEIGHBOUR_SHARE",
    "RADIUS_SIGMA_REL",
    "explained_in_view",
    "in_zone",
    "settled",
    "too_small",
    "tracking_config",
    "unexplained",
    "unmeasured_sighting",
]

CENTRE_SIGMA_REL = 0.32
"""1σ of each image coordinate of a partly seen fruit's circle centre, as a share of the
fruit's true apparent radius: the rms over the refusals of fruit seen in part within one
radius of a true fruit's image, in every-fruit episodes of the five truss scenarios
(``python benchmarks/bench_unmeasured.py``: seed 8642, 20 episodes each, 3,758 refusals,
0.322 / 0.321; held-out seed 6464, 10 each, 0.330 / 0.315). Its median is 0.13: heavy-tailed."""

RADIUS_SIGMA_REL = 0.45
"""1σ of a partly seen fruit's apparent radius, relative: the rms of (circle radius / true
apparent radius - 1) over the same refusals (0.444; 6464: 0.445; median -0.08, and 5% of them
under a ninth of the true radius: a short arc is often a fragment's curve). The range its size
gives is that uncertain: what fixes the fruit in 3-D is its bearing from several views."""

CONFIRM_VIEWS = 2
"""A fruit seen in part is confirmed by this many views (the measured tracks want
``tracking.confirm_hits``, 3). The third view guards a measured track against a false
detection on another's ray, which would claim a fruit that is not there; a false confirmation
here only makes the episode say it did not find every fruit (``incomplete``), while a fruit
seen in part from two views and not confirmed lets it claim every fruit with one missing
(``truss_cluster`` 2575873638 of seed 2468: two hidden fruit, each seen in part from two views
7 and 11 mm from its true centre, and the episode ended ``converged``)."""

IN_VIEW_SHARE = 0.6
"""A weak sighting whose circle's centre lies within this share of a tracked fruit's apparent
radius of that fruit's image centre is that fruit, partly hidden (:func:`explained_in_view`)."""

NO_NEIGHBOUR_SHARE = 0.5
"""Two fruit touch at the sum of their radii; a fruit seen in part whose centre lies within a
track's radius plus this share of its own radius of the track's centre is no neighbour but
that track's fruit, its circle fitted to a part of it (a short arc's circle is often too
small, which puts it too far along the ray). Half a radius leaves room for the error of a
real neighbour's estimate."""

EXPLAINED_PROBABILITY = 0.999
"""A fruit seen in part is a measured track's fruit when their centres agree at this level
(χ², 3 components, both covariances), or when its centre lies inside the track's sphere."""


def tracking_config(tracking: TrackingConfig) -> TrackingConfig:
    """The settings of the tracker of fruit seen in part: the measured tracks', confirmed by
    :data:`CONFIRM_VIEWS` views (or fewer where ``tracking.confirm_hits`` asks for fewer)."""
    return dataclasses.replace(tracking, confirm_hits=min(tracking.confirm_hits, CONFIRM_VIEWS))


def unmeasured_sighting(
    bearing_camera: np.ndarray,
    radius_px: float,
    focal_px: float,
    p_world_camera: np.ndarray,
    R_world_camera: np.ndarray,
) -> Sighting | None:
    """The weak sighting z = (t_y/t_x, t_z/t_x, α) of a fruit seen in part, from the circle its
    arcs lie on: the unit ray through its centre in the camera frame (x optical axis, y
    left, z up) and its radius [px] (α = atan(r / f)), with the noise of
    :data:`CENTRE_SIGMA_REL` and :data:`RADIUS_SIGMA_REL`; None for a circle that is no fruit
    in front of the camera (a ray not ahead, a radius not > 0)."""
    b = np.asarray(bearing_camera, dtype=float)
    if b.shape != (3,) or not np.all(np.isfinite(b)) or b[0] <= 1e-3 * float(np.linalg.norm(b)):
        return None
    if not (math.isfinite(radius_px) and radius_px > 0.0 and focal_px > 0.0):
        return None
    alpha = math.atan(radius_px / focal_px)
    s_c = CENTRE_SIGMA_REL * radius_px / focal_px
    s_a = RADIUS_SIGMA_REL * alpha
    cov = np.diag([s_c**2, s_c**2, s_a**2])
    z = np.array([b[1] / b[0], b[2] / b[0], alpha])
    return Sighting(z, BearingSizeModel(p_world_camera, R_world_camera, cov))


def too_small(sighting: Sighting, zone_centre_m: np.ndarray, zone_m: float, radius_min_m: float) -> bool:
    """Whether a weak sighting's circle is smaller than any fruit of the work zone looks from its
    camera: the smallest fruit the prior allows (``radius_min_m``), at the zone's far edge (the
    camera's distance to its centre plus ``zone_m``), would look bigger. Such a circle is a
    fragment's curve (a stem, a sepal, a short stretch of a neighbour's rim), not a fruit's.
    ``python benchmarks/bench_unmeasured.py --episodes 10`` (seed 8642, 2,084 refusals on a
    true fruit): the circles under a quarter of the true apparent radius lie 0.76 of it off
    (rms), 7.5 times their own radius; those at a quarter to a half, 0.66 and 1.9 times (the
    noise above assumes 0.32 of the circle's radius). This rule drops 100% and 96% of them,
    40% of those at 0.5-0.8 of the true radius (0.49 off, 0.80 of their own) and none of the
    1,249 above (0.26 off)."""
    p = sighting.model.p_world_camera
    far = float(np.linalg.norm(np.asarray(zone_centre_m, dtype=float) - p)) + zone_m
    return float(sighting.z[2]) < math.asin(min(max(radius_min_m, 0.0) / far, 1.0))


def explained_in_view(sighting: Sighting, tracks: Sequence[Track]) -> bool:
    """Whether a weak sighting is the part of a tracked fruit that shows in its view: the
    centre of its circle within :data:`IN_VIEW_SHARE` of a track's apparent radius of that
    track's image (a tracked fruit partly hidden in one view is no new fruit; a fruit whose
    centre hides behind a tracked one's middle shows too little to count anyway)."""
    for t in tracks:
        offset = image_offset(sighting, t.belief)
        if offset is not None and offset[0] < IN_VIEW_SHARE:
            return True
    return False


def _within_neighbour(h: Track, t: Track) -> bool:
    """Whether ``h``'s centre lies nearer ``t``'s than a neighbour's could (see
    :data:`NO_NEIGHBOUR_SHARE`) and no view that measured ``t`` saw ``h`` in part (one image
    does not both measure a fruit and see it in part: that was another fruit, and a weak
    track holding it holds evidence of that fruit wherever its mean lies): ``h`` is ``t``'s
    fruit."""
    near = float(np.linalg.norm(h.centre_m - t.centre_m)) < t.radius_m + NO_NEIGHBOUR_SHARE * h.radius_m
    return near and not (h.views & t.views)


def settled(seen_in_part: Sequence[Track], tracks: Sequence[Track]) -> list[tuple[Track, Track]]:
    """The fruit seen in part, placed by two viewpoints or more, that a measured track placed
    to within its radius (:attr:`~bve_mj.estimation.tracks.Track.triangulated`) shows to be
    its own fruit (:func:`_within_neighbour`), each with that track. The loop forgets them
    before it fuses a view's evidence: a fruit seen in part before it was measured is that
    fruit, and its track, kept, gates the next views' evidence of a neighbour hidden behind it
    and absorbs it (``ripe_truss`` 67249277 of seed 1357: a track begun on the target, seen in
    part, took a hidden neighbour's partial outlines from four views, stayed 22-28 mm from
    both, was explained by the target's track, and the episode claimed every fruit with that
    neighbour missing)."""
    out = []
    for h in seen_in_part:
        if len(h.viewpoints) < 2 or not np.all(np.isfinite(h.belief.mean)):
            continue
        for t in tracks:
            if t.triangulated and _within_neighbour(h, t):
                out.append((h, t))
                break
    return out


def in_zone(tracks: Sequence[Track], zone_centre_m: np.ndarray, zone_m: float) -> list[Track]:
    """The ``tracks`` whose centre lies within ``zone_m`` of ``zone_centre_m``: the fruit seen in
    part the episode takes for evidence (and for obstacles). A weak track beyond is one gone
    astray (its range from a sliver of outline); in ``cherry_truss`` 1593483900 of seed 2469
    one lay 0.2 m behind the robot's base, 3σ within its radius, and as an obstacle put the
    canopy's front behind the arm: every move was refused for 13 views."""
    c = np.asarray(zone_centre_m, dtype=float)
    return [h for h in tracks if float(np.linalg.norm(h.centre_m - c)) <= zone_m]


def unexplained(
    seen_in_part: Sequence[Track], tracks: Sequence[Track], zone_centre_m: np.ndarray, zone_m: float
) -> list[Track]:
    """The confirmed fruit seen in part that lie in the work zone (centre within ``zone_m`` of
    ``zone_centre_m``: :func:`in_zone`) and that no measured track explains: their centre
    farther from every track's than a neighbour's could lie (the track's radius and
    :data:`NO_NEIGHBOUR_SHARE` of its own: fruit do not interpenetrate) and disagreeing at
    :data:`EXPLAINED_PROBABILITY` (χ², 3 components, the two covariances summed) with every
    track's centre; neither explains it for a track measured in a view that saw it in part
    (one image does not both measure a fruit and see it in part: that was a fruit behind it,
    :func:`_within_neighbour`)."""
    limit = nis_threshold(EXPLAINED_PROBABILITY, 3)
    out = []
    for h in in_zone(seen_in_part, zone_centre_m, zone_m):
        if not h.confirmed or not np.all(np.isfinite(h.belief.mean)):
            continue
        explained = False
        for t in tracks:
            if _within_neighbour(h, t):
                explained = True
                break
            d = h.centre_m - t.centre_m
            if h.views & t.views:
                continue
            S = h.belief.cov[:3, :3] + t.belief.cov[:3, :3]
            try:
                chi2 = float(d @ np.linalg.solve(S, d))
            except np.linalg.LinAlgError:
                continue
            if chi2 <= limit:
                explained = True
                break
        if not explained:
            out.append(h)
    return out
