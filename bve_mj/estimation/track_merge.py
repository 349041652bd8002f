"""Duplicate tracks merged: two tracks that are one fruit (the tracker's step 5,
:mod:`bve_mj.estimation.tracks`).

Each track's belief is its own detections and the radius prior (and, in a state that carries
them, the camera's calibration biases' prior), so their information adds, less the priors
counted twice (:func:`fused_belief`). Two tracks are merged when they
agree (χ² of the difference of their states, ``merge_probability``) and, for two confirmed
tracks, their centres lie closer than a fruit's radius. Two tentative tracks of one fruit are
two rays that cross at it (each long along its ray), so for them agreement alone decides; two
with a view in common are two things in one image, whose rays from one camera agree near it
and cross nowhere: they never merge by agreement. Two tracks whose centres lie closer than a
fruit's radius are one fruit whatever their beliefs say (fruit cannot overlap): when they
disagree, their fused belief is widened by χ²/4 (they differ more than their covariances
allow: a bias), or, with a view in common, the one with more detections stays as it is.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from bve_mj.errors import EstimationError
from bve_mj.estimation.belief import Belief
from bve_mj.estimation.ekf import nis_threshold
from bve_mj.estimation.sensor_share import added, calibration_information

if TYPE_CHECKING:
    from bve_mj.estimation.tracks import Track

__all__ = ["fused_belief", "merge_duplicates"]


def merge_duplicates(
    tracks: list[Track],
    radius_prior: tuple[float, float],
    merge_probability: float,
    confirm_hits: int,
    calibration_sigmas: tuple[float, float, float] | None = None,
) -> list[tuple[int, int]]:
    """Merge the duplicates among ``tracks`` in place (see the module docstring): the track
    with more detections (the older one on a tie) keeps the other's detections, views and
    viewpoints (confirmed once they number ``confirm_hits``); the other leaves the list.
    Two tracks agree or not by their (centre, radius): the calibration biases a state may
    carry are the camera's, not the fruit's. Returns the (dropped id, kept id) pairs in order."""
    merges: list[tuple[int, int]] = []
    limit = nis_threshold(merge_probability, 4)
    merged = True
    while merged:
        merged = False
        for a, b in _pairs(tracks):
            d = a.belief.mean[:4] - b.belief.mean[:4]
            chi2 = float(d @ np.linalg.solve(a.belief.cov[:4, :4] + b.belief.cov[:4, :4], d))
            close = float(np.linalg.norm(a.centre_m - b.centre_m)) < 0.5 * (a.radius_m + b.radius_m)
            if chi2 > limit and not close:
                continue  # two fruit: their fused belief is not needed
            fused = fused_belief(a.belief, b.belief, radius_prior, calibration_sigmas)
            both = a.confirmed and b.confirmed
            # two rays from one camera agree near it without crossing at a fruit: tracks
            # with a view in common (two things in one image) never merge by agreement
            agree = fused is not None and chi2 <= limit and not (a.views & b.views)
            if (agree and (close or not both)) or close:
                keep, drop = (a, b) if (a.hits, -a.id) >= (b.hits, -b.id) else (b, a)
                if fused is not None and (agree or not (a.views & b.views)):
                    keep.belief = fused if agree else Belief(fused.mean, fused.cov * max(chi2 / 4.0, 1.0))
                    prior = calibration_information(fused.dim, calibration_sigmas)  # counted once
                    both_info = added(a.sensor_info, b.sensor_info)
                    keep.sensor_info = both_info if both_info is None or prior is None else both_info - prior
                keep.hits += drop.hits
                keep.views |= drop.views
                for q in drop.viewpoints:
                    keep.note_viewpoint(q)
                keep.confirmed = keep.confirmed or drop.confirmed or len(keep.viewpoints) >= confirm_hits
                keep.innovations += drop.innovations
                keep.directions += drop.directions
                keep.cameras += drop.cameras
                keep.outlines += drop.outlines
                keep.last_view = max(keep.last_view, drop.last_view)
                tracks.remove(drop)
                merges.append((drop.id, keep.id))
                merged = True
                break
    return merges


def fused_belief(
    a: Belief,
    b: Belief,
    radius_prior: tuple[float, float],
    calibration_sigmas: tuple[float, float, float] | None = None,
) -> Belief | None:
    """The belief of two tracks of one fruit: their information added, the radius prior's
    (mean, σ) and, in a state that carries them, the calibration biases' N(0, σ²) counted
    once (each holds them). None when it is not positive definite."""
    r0, sr = radius_prior
    n = a.dim
    prior_info = np.zeros((n, n))
    prior_info[3, 3] = 1.0 / sr**2
    if n == 7 and calibration_sigmas is not None:
        prior_info[4:, 4:] = np.diag(1.0 / np.square(calibration_sigmas))
    prior_mean = np.zeros(n)
    prior_mean[3] = r0
    try:
        La, Lb = np.linalg.inv(a.cov), np.linalg.inv(b.cov)
        L = La + Lb - prior_info
        P = np.linalg.inv(L)
        x = P @ (La @ a.mean + Lb @ b.mean - prior_info @ prior_mean)
        return Belief(x, P)
    except (np.linalg.LinAlgError, EstimationError):
        return None


def _pairs(tracks: list[Track]) -> list[tuple[Track, Track]]:
    return [(a, b) for i, a in enumerate(tracks) for b in tracks[i + 1 :]]
