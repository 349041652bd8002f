"""Tracks: one belief per fruit, and how each view's detections are assigned to them.

A view measures every fruit it sees, each as z = (t_y/t_x, t_z/t_x, α) of
:class:`~bve_mj.estimation.models.BearingSizeModel` (the bearing of its centre and its
apparent angular radius). The tracker keeps one :class:`Track` per fruit (a belief over its
centre and radius, and the camera's calibration biases where the sensor declares them), and
per view:

1. **assigns** the detections to the tracks predicted visible by a globally optimal
   assignment (the Hungarian algorithm, :func:`scipy.optimize.linear_sum_assignment`) on the
   negative log-likelihood of each pair, NIS + ln det S, gated by the NIS (a detection no
   track's gate admits cannot be assigned);
2. **updates** each assigned track with its detection (the filter's update, the view
   counted as the share of a fresh view it adds beside the track's earlier views when a view
   correlation is given);
3. **starts** a track from each detection left over whose fruit lies in the work zone (and
   that is no confirmed fruit mismeasured: :func:`~bve_mj.estimation.assignment.mismeasured`):
   its bearing fixes the centre's direction, its apparent size with the fruit type's radius
   prior the range, so the belief is wide along the ray (:func:`belief_from_detection`);
4. **counts a miss** for each track predicted visible (in the image, its outline not hidden
   by another track's: :mod:`bve_mj.estimation.visibility`) that got no detection; a track
   is confirmed once its detections come from ``confirm_hits`` viewpoints (two detections of
   one view, merged, are one view's evidence; so are views within :data:`SAME_VIEWPOINT_M`
   of each other: ``ripe_truss`` 4234827545 confirmed a track 47 mm off a fruit from three
   views of one held camera), and deleted when, never confirmed, the views planned to see it
   missed it ``delete_misses`` times (predicted visible, or whatever the prediction where
   one viewpoint saw it: where it lies along its ray is unknown, and ``ripe_truss``
   601185105 planned 5 of 16 views for one such), or any views did three times that often
   (a false detection is not seen again; a real fruit the detector refuses from a poor view
   is, from a good one). A track whose detections from two views or more place
   it to within its radius (3σmax ≤ r̂: their rays cross there) is not deleted for misses:
   something stands there, and a fruit behind its neighbours is refused from most views
   (``ripe_truss`` 4203080826: the target, seen from two views to 0.3 mm, was deleted after
   three refusals and never seen again);
5. **merges** duplicates, two tracks that are one fruit
   (:func:`~bve_mj.estimation.track_merge.merge_duplicates`: when they agree, or their
   centres lie closer than a fruit's radius).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from bve_mj.config import TrackingConfig
from bve_mj.errors import EstimationError
from bve_mj.estimation.assignment import Sighting, assign, belief_from_detection, mismeasured
from bve_mj.estimation.belief import Belief
from bve_mj.estimation.ekf import UpdateResult, nis_threshold
from bve_mj.estimation.models import BearingSizeModel
from bve_mj.estimation.noise import Outline
from bve_mj.estimation.outliers import OutlierMixture, mixture_update
from bve_mj.estimation.sensor_share import added, calibration_information, measurement_information
from bve_mj.estimation.track_merge import merge_duplicates
from bve_mj.estimation.view_correlation import ViewCorrelation, discounted, new_view_share, shared_dof
from bve_mj.geometry import unit

__all__ = ["Sighting", "Track", "TrackEvent", "Tracker", "ViewTracking", "assign", "belief_from_detection"]

SAME_VIEWPOINT_M = 0.01
"""A view whose camera lies within this of an earlier view's is the same viewpoint: it sees
what that one saw (a held camera, a plan that barely moves), no new evidence that the fruit
is there [m]."""


@dataclass
class Track:
    """One fruit's belief and history (mutable: the :class:`Tracker` owns it).

    Attributes:
        id: unique within an episode, in order of creation.
        belief: over the centre [m] and radius [m], (4,), and the camera's calibration
            biases (7,) when the tracker carries them.
        hits: detections assigned (the first, which started it, included).
        misses: views that should have seen it (predicted visible) and did not.
        failed: views planned to see it (its turn in the planner) that did not.
        expected: views in which it was predicted visible.
        confirmed: its detections came from the confirmation count of viewpoints, once (two
            tracks started in one view and merged are one view's evidence, not two; a camera
            held where it was sees what it saw: one viewpoint, however many views).
        first_view, last_view: the views that started it and last saw it.
        innovations: (NIS, degrees of freedom: its share of a fresh view, :func:`~bve_mj.estimation.
            view_correlation.shared_dof`) of its assigned detections after the first.
        directions: unit directions fruit → camera of the views fused, for the correlation of
            views from nearby directions (the first's included).
        cameras: the camera positions of those views [m], for the part views from nearby
            places share.
        outlines: what the detector saw of the fruit in each of those views (None where not
            known), for the claims' offset (:meth:`~bve_mj.estimation.noise.NoiseModel.
            centre_offset_cov`).
        views: the views whose detections it holds.
        viewpoints: the camera positions of those views, those within
            :data:`SAME_VIEWPOINT_M` of an earlier one left out [m].
        sensor_info: S, the information the declared sensor errors hold in its belief (the
            calibration biases' prior, encoder noise: :mod:`bve_mj.estimation.sensor_share`),
            None where none.
    """

    id: int
    belief: Belief
    first_view: int
    last_view: int
    hits: int = 1
    misses: int = 0
    failed: int = 0
    expected: int = 0
    confirmed: bool = False
    innovations: list[tuple[float, float]] = field(default_factory=list)
    directions: list[np.ndarray] = field(default_factory=list)
    cameras: list[np.ndarray] = field(default_factory=list)
    outlines: list[Outline | None] = field(default_factory=list)
    views: set[int] = field(default_factory=set)
    viewpoints: list[np.ndarray] = field(default_factory=list)
    sensor_info: np.ndarray | None = None

    @property
    def centre_m(self) -> np.ndarray:
        return self.belief.centre_m

    @property
    def radius_m(self) -> float:
        r = self.belief.radius_m
        return float(r) if r is not None else float("nan")

    @property
    def missed_share(self) -> float:
        """The share of the views expected to see it that did not."""
        return self.misses / self.expected if self.expected else 0.0

    @property
    def triangulated(self) -> bool:
        """Detections from two viewpoints or more place it to within its radius (3σmax ≤ r̂)."""
        return len(self.viewpoints) >= 2 and 3.0 * self.belief.sigma_max_m <= self.radius_m

    def note_viewpoint(self, p_world_camera: np.ndarray) -> None:
        """Count the camera position of a view that detected it, unless within
        :data:`SAME_VIEWPOINT_M` of one counted."""
        p = np.asarray(p_world_camera, dtype=float)
        if all(float(np.linalg.norm(p - q)) >= SAME_VIEWPOINT_M for q in self.viewpoints):
            self.viewpoints.append(p.copy())


@dataclass(frozen=True)
class TrackEvent:
    """What happened to a track in a view: ``started``, ``updated``, ``missed``, ``confirmed``,
    ``deleted``, ``merged`` (into ``other``)."""

    kind: str
    track: int
    other: int | None = None


@dataclass(frozen=True)
class ViewTracking:
    """What the tracker made of one view.

    Attributes:
        assigned: (detection index, track id) pairs.
        started: (detection index, track id) pairs: the tracks started from detections.
        ignored: detection indices neither assigned nor started (outside the work zone,
            within another track's gate but not assigned to it, or a known fruit mismeasured).
        expected: track ids predicted visible in this view.
        events: every :class:`TrackEvent` in order.
        assign_s: wall time of the association alone (the NIS of every track and detection
            and the optimal assignment) [s]; the updates, starts and merges not included.
    """

    assigned: tuple[tuple[int, int], ...]
    started: tuple[tuple[int, int], ...]
    ignored: tuple[int, ...]
    expected: tuple[int, ...]
    events: tuple[TrackEvent, ...]
    assign_s: float = 0.0


class Tracker:
    """Every fruit of the work zone, one :class:`Track` each (see the module docstring).

    Args:
        config: the tracking settings (gate, confirmation, deletion, merging, zone).
        zone_centre_m: the centre of the work zone (the target's prior estimate) [m], (3,).
        radius_prior: (mean, σ) of the fruit type's radius [m], for new tracks.
        update: the filter's update (belief, z, model, gate) → :class:`UpdateResult`.
        visible: ``visible(centres (n, 3), radii (n,), model) → (n,) bool``: which tracks the
            camera of ``model`` (the view's) should see (in the image, outline not hidden).
        correlation: how views from nearby directions share their errors (centre, radius);
            None: views are independent.
        calibration_sigmas: σ of the camera's calibration biases (δy, δz [rad], ε) when the
            sensor declares them: each track's state then carries them (7,), as the
            one-target filter's does (each track estimates them from its own detections; a
            bias left out of the state made tracks claim millimetres they did not have).
        outliers: the share of views that err several times the noise model's σ and by how
            much (:mod:`bve_mj.estimation.outliers`): each detection is fused under that
            mixture. None: Gaussian.
    """

    def __init__(
        self,
        config: TrackingConfig,
        zone_centre_m: np.ndarray,
        radius_prior: tuple[float, float],
        update: Callable[..., UpdateResult],
        visible: Callable[[np.ndarray, np.ndarray, BearingSizeModel], np.ndarray],
        correlation: tuple[ViewCorrelation, ViewCorrelation] | None = None,
        calibration_sigmas: tuple[float, float, float] | None = None,
        outliers: OutlierMixture | None = None,
    ) -> None:
        self.config = config
        self.outliers = outliers if outliers is not None else OutlierMixture()
        self.calibration_sigmas = calibration_sigmas
        self.zone_centre_m = np.asarray(zone_centre_m, dtype=float).copy()
        self.radius_prior = radius_prior
        self._update = update
        self._visible = visible
        self._correlation = correlation
        self.tracks: list[Track] = []
        self.dropped: list[Track] = []  # deleted before they were confirmed
        self._next_id = 0

    # ------------------------------------------------------------------ queries
    def track(self, track_id: int) -> Track:
        for t in self.tracks:
            if t.id == track_id:
                return t
        raise KeyError(track_id)

    @property
    def confirmed(self) -> list[Track]:
        return [t for t in self.tracks if t.confirmed]

    def predicted_visible(self, model: BearingSizeModel) -> np.ndarray:
        """(n_tracks,) bool: which tracks the camera of ``model`` should see."""
        if not self.tracks:
            return np.zeros(0, dtype=bool)
        centres = np.array([t.centre_m for t in self.tracks])
        radii = np.array([t.radius_m for t in self.tracks])
        return np.asarray(self._visible(centres, radii, model), dtype=bool)

    def seed(self, belief: Belief, view: int) -> Track:
        """Start a confirmed track from a given belief (the target the episode was asked for)."""
        t = Track(self._next_id, belief, view, view, confirmed=True)
        t.sensor_info = calibration_information(belief.dim, self.calibration_sigmas)
        self._next_id += 1
        self.tracks.append(t)
        return t

    def forget(self, tracks: Sequence[Track] | None = None) -> None:
        """Remove ``tracks`` (by identity; every track when None): what the caller learned
        they are not (a fruit seen in part that a measured track shows to be its own), not a
        deletion for misses (:attr:`dropped` does not count them)."""
        if tracks is None:
            self.tracks.clear()
            return
        self.tracks[:] = [t for t in self.tracks if all(t is not g for g in tracks)]

    # ------------------------------------------------------------------ a view
    def step(
        self,
        sightings: Sequence[Sighting],
        camera: BearingSizeModel,
        view: int,
        planned_for: int | None = None,
    ) -> ViewTracking:
        """Assign this view's sightings, update, start, count misses, confirm, delete, merge.
        ``camera``: a model at the view's camera pose (its noise unused), for visibility;
        ``planned_for``: the track the view was planned to see.

        Every track may be assigned a detection (a fruit predicted hidden may still show);
        only a track predicted visible counts a miss when it gets none. A detection left over
        that lies within some track's gate is not a new fruit (a fragment, or a fruit two
        tracks compete for): it is ignored."""
        cfg = self.config
        events: list[TrackEvent] = []
        seen = self.predicted_visible(camera)
        expected = [t for t, s in zip(self.tracks, seen, strict=True) if s]
        tracks = list(self.tracks)
        t0 = time.perf_counter()
        pairs, nis = assign([t.belief for t in tracks], sightings, cfg.gate_probability)
        assign_s = time.perf_counter() - t0
        assigned: list[tuple[int, int]] = []
        for i, j in pairs:
            self._fuse(tracks[i], sightings[j], view, events)
            assigned.append((j, tracks[i].id))
        done = {j for j, _ in assigned}
        got = {tid for _, tid in assigned}
        for t in expected:
            t.expected += 1
            if t.id not in got:
                t.misses += 1
                events.append(TrackEvent("missed", t.id))
        aimed = next((t for t in tracks if t.id == planned_for and t.id not in got), None)
        if aimed is not None and (aimed.id in {e.id for e in expected} or len(aimed.viewpoints) < 2):
            aimed.failed += 1
        gate = nis_threshold(cfg.gate_probability, 3)
        started: list[tuple[int, int]] = []
        ignored: list[int] = []
        for j, s in enumerate(sightings):
            if j in done:
                continue
            gated = nis.shape[0] > 0 and bool(np.any(nis[:, j] <= gate))
            known = mismeasured(s, [t.belief for t in self.tracks if t.confirmed and t.triangulated])
            fresh = None if gated or known else self._start(s, view)
            if fresh is None:
                ignored.append(j)
                continue
            started.append((j, fresh.id))
            events.append(TrackEvent("started", fresh.id))
        events += [
            TrackEvent("merged", dropped, kept)
            for dropped, kept in merge_duplicates(
                self.tracks,
                self.radius_prior,
                self.config.merge_probability,
                self.config.confirm_hits,
                self.calibration_sigmas,
            )
        ]
        for t in list(self.tracks):
            missed = t.failed >= cfg.delete_misses or t.misses >= 3 * cfg.delete_misses
            if not t.confirmed and missed and not t.triangulated:
                self.tracks.remove(t)
                self.dropped.append(t)
                events.append(TrackEvent("deleted", t.id))
        return ViewTracking(
            tuple(assigned), tuple(started), tuple(ignored), tuple(t.id for t in expected), tuple(events),
            assign_s,
        )  # fmt: skip

    def _fuse(self, t: Track, s: Sighting, view: int, events: list[TrackEvent]) -> None:
        model = s.model
        direction = unit(model.p_world_camera - t.centre_m)
        camera = np.asarray(model.p_world_camera, dtype=float).copy()
        centre_share = radius_share = 1.0  # a fresh view's
        if self._correlation is not None and t.directions:
            taken, at = np.array(t.directions), np.array(t.cameras)
            centre_share = new_view_share(self._correlation[0], taken, direction, at, camera)[0]
            radius_share = new_view_share(self._correlation[1], taken, direction, at, camera)[0]
            model = discounted(model, centre_share, radius_share)  # type: ignore[assignment]
        result, _ = mixture_update(self._update, t.belief, s.z, model, self.outliers)
        t.belief = result.belief
        t.sensor_info = added(t.sensor_info, measurement_information(model, s.sensor_cov, result.belief.mean))
        t.hits += 1
        t.views.add(view)
        t.note_viewpoint(s.model.p_world_camera)
        t.last_view = view
        t.innovations.append((result.nis, shared_dof(model, 3, centre_share, radius_share)))
        t.directions.append(direction)
        t.cameras.append(camera)
        t.outlines.append(s.outline)
        events.append(TrackEvent("updated", t.id))
        if not t.confirmed and len(t.viewpoints) >= self.config.confirm_hits:
            t.confirmed = True
            events.append(TrackEvent("confirmed", t.id))

    def _start(self, s: Sighting, view: int) -> Track | None:
        """A new track from sighting ``s``, if its fruit may lie in the work zone (the stretch
        of its ray within 3σ of the range its size gives passes within ``zone_m`` of the zone's
        centre) and in range."""
        cfg = self.config
        try:
            belief = belief_from_detection(s, *self.radius_prior, self.calibration_sigmas)
        except EstimationError:
            return None
        p = s.model.p_world_camera
        ray = belief.centre_m - p
        rng = float(np.linalg.norm(ray))
        sd = 3.0 * rng * self.radius_prior[1] / self.radius_prior[0]
        along = float(np.clip((self.zone_centre_m - p) @ ray / rng, rng - sd, rng + sd))
        if rng > cfg.max_range_m or np.linalg.norm(p + along * ray / rng - self.zone_centre_m) > cfg.zone_m:
            return None
        t = Track(self._next_id, belief, view, view, confirmed=cfg.confirm_hits <= 1, views={view})
        t.sensor_info = added(
            calibration_information(belief.dim, self.calibration_sigmas),
            measurement_information(s.model, s.sensor_cov, belief.mean),
        )  # the detection is its first measurement (its belief is the prior's update by it)
        t.directions.append(unit(s.model.p_world_camera - belief.centre_m))
        t.cameras.append(np.asarray(s.model.p_world_camera, dtype=float).copy())
        t.outlines.append(s.outline)
        t.note_viewpoint(s.model.p_world_camera)
        self._next_id += 1
        self.tracks.append(t)
        return t

    def snapshot(self) -> tuple[Track, ...]:
        """Copies of the tracks (for records: later views do not change them)."""
        copies = {"innovations": list, "directions": list, "cameras": list, "views": set, "viewpoints": list}
        copies["outlines"] = list
        return tuple(
            dataclasses.replace(t, **{k: make(getattr(t, k)) for k, make in copies.items()})
            for t in self.tracks
        )
