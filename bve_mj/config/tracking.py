"""Settings of multi-fruit tracking: every ripe tomato in the work zone, one track each."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from bve_mj.config.fields import (
    FruitsMode,
    _choice,
    _number,
    _open_interval,
    _positive,
    _positive_int,
    _why,
)
from bve_mj.errors import ConfigError

__all__ = ["TrackingConfig"]


@dataclass(frozen=True, kw_only=True)
class TrackingConfig:
    """Which fruit an episode localises, and how detections become tracks.

    With ``fruits = "all"`` every ripe fruit the detector measures within ``zone_m`` of the
    target's prior estimate gets a track (a belief over its centre and radius); detections are
    assigned to tracks by a globally optimal assignment on their Mahalanobis distances, a new
    track starts from one detection (its bearing, and a range from its apparent size, wide
    along the ray), is confirmed after ``confirm_hits`` assignments and deleted when, never
    confirmed, it is missed ``delete_misses`` times in views that should have seen it.
    """

    fruits: FruitsMode = field(
        default="target",
        metadata=_why(
            "target: localise the one fruit the episode's prior points at (the paper's task); all: "
            "every ripe fruit within zone_m of it, one track each, and plan views for all of them"
        ),
    )
    zone_m: float = field(
        default=0.15,
        metadata=_why(
            "the work zone: ripe fruit whose centre lies within this of the target's prior estimate "
            "are tracked (a truss of 4-8 fruit spans 0.1-0.25 m); fruit beyond are another truss",
            "m",
        ),
    )
    max_range_m: float = field(
        default=0.8,
        metadata=_why("detections whose range exceeds this are ignored (the next row)", "m"),
    )
    gate_probability: float = field(
        default=0.99999,
        metadata=_why(
            "a detection may be assigned to a track when its NIS is below the chi-square quantile "
            "of this probability (3 components)"
        ),
    )
    confirm_hits: int = field(
        default=3,
        metadata=_why(
            "a track is confirmed after detections from this many viewpoints (views 1 cm apart or "
            "more): two views of anything fix a point "
            "with nothing to check it (a false detection lying on another's ray from the second "
            "view would confirm a fruit that is not there: 7 of 80 synthetic trusses with two "
            "false detections at 2, none at 3); a third checks it, and localising takes three anyway"
        ),
    )
    delete_misses: int = field(
        default=3,
        metadata=_why(
            "a track never confirmed is deleted after this many views planned to see it missed it, "
            "or three times as many views that should have seen it (in the image, its outline not "
            "hidden by another track's); one that two views place to within its radius is kept"
        ),
    )
    merge_probability: float = field(
        default=0.999,
        metadata=_why(
            "two tracks whose states agree at this level (chi-square, 4 components: centre and "
            "radius) are one fruit, merged (two confirmed tracks only when also closer than their "
            "mean radius)"
        ),
    )
    explore_span_deg: float = field(
        default=40.0,
        metadata=_why(
            "before the episode says it found every fruit, its views must span this angle around "
            "the work zone (directions seen from its centre): a fruit hidden behind its neighbours "
            "from one side shows from another. Until then, once every track is localised, the BVE "
            "plans for the zone itself, away from the views taken; 0 = no exploration",
            "deg",
        ),
    )
    zone_framed_share: float = field(
        default=1.0,
        metadata=_why(
            "before the episode says it found every fruit, its images must have framed this share "
            "of the work zone (a grid of points a quarter of zone_m apart, each at least half a "
            "fruit's apparent radius inside the image): a fruit outside every image was never "
            "seen. Until then, once every track is localised, the BVE looks where a view frames "
            "most of what is not framed yet; 0 = no such check",
        ),
    )
    zone_behind_fruit: bool = field(
        default=False,
        metadata=_why(
            "before the episode says it found every fruit, the places where a neighbour of a known "
            "fruit would sit (within two radii of touching it) must have been shown past the known "
            "fruit: the views would have measured a fruit there as surely as one clear view does, "
            "from the outline each shows of it and the share of such views the detector measures. "
            "Off: a place counts as seen once in an image (a fruit hidden behind the front row "
            "can go unnoticed: truss_cluster 428971644); on: such episodes end incomplete, and "
            "so do most whose views all come from one side of the truss"
        ),
    )
    candidates: int = field(
        default=2,
        metadata=_why(
            "per view, the BVE plans a viewpoint for each of this many least localised fruit; the "
            "one with the most joint information (sum over tracks) is taken"
        ),
    )
    unhide: bool = field(
        default=True,
        metadata=_why(
            "where a fruit's BVE view would not show its outline (behind its neighbours, as the "
            "tracks predict it), plan instead a view from which it would, within the step and "
            "the task's constraints, reached by the arm's IK (the most outline first; where none "
            "within a step shows it, a step towards the side that does)"
        ),
    )
    pick_rounds: int = field(
        default=0,
        metadata=_why(
            "with episode.approach, the harvest picks each fruit it visits (the fruit and its "
            "calyx leave the scene: what a picking arm does), then the survey goes on for the "
            "fruit the picked ones hid, up to this many times (each with the view budget "
            "episode.views); a round that picks nothing ends it. 0: the harvest only visits"
        ),
    )

    def __post_init__(self) -> None:
        _choice("tracking", "fruits", self.fruits, FruitsMode)
        for name in ("zone_m", "max_range_m"):
            _positive("tracking", name, getattr(self, name))
        for name in ("gate_probability", "merge_probability"):
            _open_interval("tracking", name, getattr(self, name), 0.0, 1.0, "a probability in (0, 1)")
        _positive_int("tracking", "confirm_hits", self.confirm_hits, 100)
        _positive_int("tracking", "delete_misses", self.delete_misses, 100)
        _positive_int("tracking", "candidates", self.candidates, 32)
        for name in ("unhide", "zone_behind_fruit"):
            if not isinstance(getattr(self, name), bool):
                raise ConfigError(f"tracking.{name}", getattr(self, name), "true or false")
        rounds = self.pick_rounds
        if isinstance(rounds, bool) or not isinstance(rounds, (int, np.integer)) or not 0 <= rounds <= 10:
            raise ConfigError("tracking.pick_rounds", rounds, "an integer in [0, 10]")
        if not 0.0 <= _number("tracking", "zone_framed_share", self.zone_framed_share) <= 1.0:
            raise ConfigError("tracking.zone_framed_share", self.zone_framed_share, "a number in [0, 1]")
        if not 0.0 <= _number("tracking", "explore_span_deg", self.explore_span_deg) <= 180.0:
            raise ConfigError("tracking.explore_span_deg", self.explore_span_deg, "a number in [0, 180]")
        if _number("tracking", "zone_m", self.zone_m) > self.max_range_m:
            raise ConfigError(
                "tracking.zone_m", self.zone_m, f"a number <= max_range_m ({self.max_range_m:g})"
            )
