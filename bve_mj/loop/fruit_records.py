"""What an every-fruit episode leaves: each track as a view left it, a record per view, and the
finished episode (:mod:`bve_mj.loop.every_fruit` makes them)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from bve_mj.estimation.belief import Belief
from bve_mj.estimation.claim_shape import GAUSSIAN, ClaimShape
from bve_mj.estimation.sensor_share import sensor_share
from bve_mj.estimation.tracks import Track, ViewTracking
from bve_mj.loop.claims import Claims
from bve_mj.loop.events import Event
from bve_mj.loop.outcomes import Outcome
from bve_mj.planning.plan import PlanStatus
from bve_mj.sim.scene_model import Fruit

__all__ = ["FruitMatch", "FruitState", "FruitsResult", "FruitsView", "claimed"]


@dataclass(frozen=True)
class FruitState:
    """A track as a view left it.

    Attributes:
        id: the track's id.
        belief: the claimed belief over its centre and radius (the filter's with the claims).
        confirmed, hits, misses, expected: see :class:`~bve_mj.estimation.tracks.Track`.
        localised: claimed σmax ≤ the stop threshold after enough detections.
        filter_belief: the track's own belief where the claim differs from it, else None.
        sensor_cov: the share of ``belief``'s covariance the declared sensor errors make,
            which the claim keeps whole (:class:`~bve_mj.loop.records.ViewRecord`), else None.
    """

    id: int
    belief: Belief
    confirmed: bool
    hits: int
    misses: int
    expected: int
    localised: bool
    filter_belief: Belief | None = None
    sensor_cov: np.ndarray | None = None

    def to_json(self) -> dict[str, Any]:
        """The track in an episode's ``--json``: estimate, covariance, radius, state."""
        return {
            "id": self.id,
            "estimate_m": self.belief.centre_m.tolist(),
            "covariance_m2": self.belief.cov[:3, :3].tolist(),
            "radius_mm": 1e3 * float(self.belief.mean[3]),
            "radius_sigma_mm": 1e3 * float(math.sqrt(self.belief.cov[3, 3])),
            "sigma_max_mm": 1e3 * self.belief.sigma_max_m,
            "confirmed": self.confirmed,
            "hits": self.hits,
            "misses": self.misses,
            "localised": self.localised,
        }


def claimed(track: Track, claims: Claims | None, stop_sigma_m: float, converge_after: int) -> FruitState:
    """The state a track claims: its belief with the claims (the centre's offset conditioned
    on what the detector saw of the fruit in the views the track fused, ``track.outlines``),
    and whether it is localised."""
    belief, sensor = track.belief, None
    if claims is not None:
        share = sensor_share(belief.cov, track.sensor_info)
        belief = claims.claim(belief, track.innovations, track.missed_share, track.outlines, share)
        sensor = claims.sensor_part(share, track.innovations)
    localised = track.confirmed and track.hits >= converge_after and belief.sigma_max_m <= stop_sigma_m
    return FruitState(
        track.id,
        belief,
        track.confirmed,
        track.hits,
        track.misses,
        track.expected,
        bool(localised),
        None if belief is track.belief else track.belief,
        sensor,
    )


@dataclass(frozen=True)
class FruitsView:
    """One view of an every-fruit episode: where the camera was, whom the view was planned
    for, how many fruit it detected, what the tracker did, and every track after it."""

    iteration: int
    p_world_camera: np.ndarray
    planned_for: int | None
    plan_status: PlanStatus | None
    plan_feasible: bool
    plan_s: float
    track_s: float
    detections: int
    tracking: ViewTracking
    fruits: tuple[FruitState, ...]
    world: dict[str, object] | None = None
    events: tuple[Event, ...] = ()
    unmeasured: tuple[FruitState, ...] = ()
    """The fruit seen in part from enough views and explained by no track after this view
    (:func:`~bve_mj.estimation.unmeasured.unexplained`; never localised)."""
    zone_framed: float = math.nan
    """The share of the work zone framed by this view or an earlier one
    (:class:`~bve_mj.planning.zone_coverage.ZoneCoverage`; nan when the loop has none)."""


@dataclass(frozen=True)
class FruitsResult:
    """A finished every-fruit episode. ``shape``: the shape of what its tracks claim (each
    :class:`FruitState`'s belief is the claim's bound: :class:`~bve_mj.loop.records.
    EpisodeResult` says how)."""

    views: tuple[FruitsView, ...]
    wall_s: float
    outcome: Outcome
    shape: ClaimShape = GAUSSIAN

    @property
    def final(self) -> tuple[FruitState, ...]:
        return self.views[-1].fruits if self.views else ()

    @property
    def unmeasured(self) -> tuple[FruitState, ...]:
        """The fruit seen in part but never measured, at the end (see :class:`FruitsView`)."""
        return self.views[-1].unmeasured if self.views else ()


@dataclass(frozen=True)
class FruitMatch:
    """A true ripe fruit and the confirmed track matched to it (None when none was); ``shape``
    the shape of the track's claim (its belief is the bound: :attr:`claim` is the claim)."""

    fruit: Fruit
    track: FruitState | None
    shape: ClaimShape = GAUSSIAN

    @property
    def claim(self) -> Belief | None:
        """What the track claims: its bound's mean, the covariance of the claim's shape."""
        return None if self.track is None else self.shape.claim(self.track.belief, self.track.sensor_cov)

    @property
    def error_mm(self) -> float:
        if self.track is None:
            return math.nan
        return 1e3 * float(np.linalg.norm(self.track.belief.centre_m - self.fruit.centre_m))

    @property
    def nees(self) -> float:
        """The NEES of the claim (its covariance, not its bound's)."""
        claim = self.claim
        return math.nan if claim is None else claim.mahalanobis_sq(self.fruit.centre_m)

    @property
    def filter_nees(self) -> float:
        """The NEES of the track's own belief (before the claims; :attr:`nees` where none)."""
        if self.track is None:
            return math.nan
        own = self.track.belief if self.track.filter_belief is None else self.track.filter_belief
        return own.mahalanobis_sq(self.fruit.centre_m)

    def localised_within(self, mm: float) -> bool:
        return self.track is not None and self.track.localised and self.error_mm <= mm
