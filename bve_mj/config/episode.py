"""Settings of the detector, the injected faults and the closed-loop episode."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from bve_mj.config.experiments import EXPERIMENTS
from bve_mj.config.fields import (
    DetectorKind,
    PriorKind,
    _choice,
    _non_negative,
    _number,
    _open_interval,
    _positive,
    _positive_int,
    _why,
)
from bve_mj.errors import ConfigError

__all__ = ["DetectorConfig", "EpisodeConfig", "FaultConfig"]


@dataclass(frozen=True, kw_only=True)
class DetectorConfig:
    """Which detector measures the fruit, and the built-in one's settings: colour segmentation,
    separation of touching fruit (outline arcs grouped into circles), and circle (cone) fit of
    the target tomato, with the checks that refuse a poor one. ``kind = "synthetic_boxes"``
    replaces it with boxes from the true projection of the fruit in view (``box_noise_px``,
    ``miss_p``, ``false_positives``) through the box adapter
    (:mod:`bve_mj.perception.adapters`): a learned detector's effect, studied."""

    kind: DetectorKind = field(
        default="builtin",
        metadata=_why(
            "builtin: the colour detector (silhouette arcs, cone fit); synthetic_boxes: bounding "
            "boxes from the true projection of every ripe fruit in view, with corner noise, misses "
            "and false positives, measured by the box adapter (a learned detector, simulated)"
        ),
    )
    red_hue_max: int = field(default=8, metadata=_why("ripe red: OpenCV hue <= this or >= red_hue_min_wrap"))
    red_hue_min_wrap: int = field(default=170, metadata=_why("ripe red wraps around hue 180"))
    min_saturation: int = field(default=110, metadata=_why("excludes pinkish highlights and grey", "0-255"))
    min_value: int = field(
        default=16, metadata=_why("excludes black: the darkest pixel that can be ripe", "0-255")
    )
    min_chroma: int = field(
        default=17,
        metadata=_why(
            "a ripe pixel's colour stands this far out of grey (max - min of R, G, B): a red fruit "
            "in the canopy's shade is dark but red, where camera noise gives dark grey any hue",
            "0-255",
        ),
    )
    min_area_px: int = field(default=25, metadata=_why("smaller blobs are noise", "px"))
    min_boundary_points: int = field(default=12, metadata=_why("fewest silhouette points for a fit"))
    outlier_px: float = field(
        default=1.5,
        metadata=_why("boundary points this far inside the fitted circle are occluder edges", "px"),
    )
    extend_hue_max: int = field(
        default=25,
        metadata=_why(
            "skin up to this hue (orange-yellow: a highlight, a blush, uneven colour) counts as ripe "
            "where it touches ripe pixels, so a red fruit's silhouette is whole; <= the ripe hue "
            "limit turns it off (stems and leaves start at 38)",
            "0-180",
        ),
    )
    ripe_class: str | None = field(
        default=None,
        metadata=_why(
            "the least ripe class that counts as ripe (red, light_red, pink, turning; orange = turning): "
            "its hue limit (ripe_hue_limits) replaces red_hue_max; None: red_hue_max decides"
        ),
    )
    corner_px: float = field(
        default=1.5,
        metadata=_why(
            "concave corners of a ripe blob's outline deeper than this cut it into arcs (where two "
            "touching fruit meet, a calyx notch, a leaf tip)",
            "px",
        ),
    )
    junction_margin: int = field(
        default=4,
        metadata=_why("outline points left out at each end of an arc at a corner (blended with a neighbour)"),
    )
    arc_tol_px: float = field(
        default=2.0,
        metadata=_why(
            "an arc belongs to a fruit's circle when half its points or more lie within this of it "
            "(or 4% of the radius) and almost none further outside",
            "px",
        ),
    )
    interior_edge: float = field(
        default=80.0,
        metadata=_why(
            "Canny threshold on the brightness (HSV value, 3x3 Sobel magnitude) of edges inside the "
            "ripe mask that count as a fruit's rim over a ripe neighbour (red on red: no outline "
            "there); such an edge joins a fruit whose circle it lies on, never makes one; 0: off",
            ">= 0",
        ),
    )
    min_arc_deg: float = field(
        default=150.0,
        metadata=_why("fewest degrees of the target's outline seen (after trimming) to measure it", "deg"),
    )
    max_fit_rms_px: float = field(
        default=0.8, metadata=_why("largest rms residual of the silhouette points kept in the fit", "px")
    )
    max_fit_sigma_px: float = field(
        default=1.0,
        metadata=_why(
            "largest 1-sigma centre uncertainty of the fit itself (short or ragged arcs: a fruit "
            "touching ripe neighbours shows no outline against them); a looser fit is refused "
            "rather than reported, a fit within it measured with its own sigma in the covariance. "
            "0.5 refused most views of whole fruit in a truss (ripe_truss: 88-95% of ripe fruit "
            "localised against 97-100% at 1.0)",
            "px",
        ),
    )
    max_outside_share: float = field(
        default=0.05,
        metadata=_why(
            "largest share of the target's outline points more than outlier_px outside its fitted "
            "circle (more: the outline is not one fruit, a merged blob)"
        ),
    )
    min_radius_px: float = field(
        default=6.0,
        metadata=_why(
            "smallest apparent radius of a fruit (a 15 mm cherry at 1.2 m); smaller circles are specks "
            "of colour",
            "px",
        ),
    )
    size_tolerance_rel: float = field(
        default=0.5,
        metadata=_why(
            "when the caller passes the expected apparent radius, a fitted radius off by more than this "
            "share (either way) is not the target (a fragment, a merged blob, another fruit)"
        ),
    )

    ambiguity_ratio: float = field(
        default=20.0,
        metadata=_why(
            "when the estimate allows two fruit and the likelier is less than this many times as "
            "likely (3-D Mahalanobis distance of each to the estimate), the view is ambiguous and "
            "measures nothing"
        ),
    )

    box_noise_px: float = field(
        default=2.0,
        metadata=_why(
            "synthetic_boxes: Gaussian sigma of each box corner coordinate; the box adapter declares "
            "it (centre sigma = this / sqrt 2, apparent radius sigma = this / 2 near the optical axis)",
            "px",
        ),
    )
    miss_p: float = field(
        default=0.0, metadata=_why("synthetic_boxes: probability that a fruit in view gets no box")
    )
    false_positives: float = field(
        default=0.0,
        metadata=_why(
            "synthetic_boxes: mean number of false boxes per image (Poisson), fruit-sized, anywhere "
            "in the image"
        ),
    )

    @staticmethod
    def ripe_hue_limits() -> dict[str, int]:
        """The OpenCV hue (0-180) up to which the coloured skin of each ripeness class reaches,
        measured on the scene's rendered skins (``bve_mj.sim.textures``) in white light: red and
        the red of light red 1-8, the yellow-orange of light red and pink up to 30-34, turning
        (and the legacy orange) 33-37; breaker and green 38-45 with the stems, leaves 45-60,
        never ripe. ``ripe_class`` picks one."""
        return {"red": 8, "light_red": 30, "pink": 34, "turning": 37, "orange": 37}

    def __post_init__(self) -> None:
        _choice("detector", "kind", self.kind, DetectorKind)
        if not 0.0 <= _number("detector", "box_noise_px", self.box_noise_px) <= 100.0:
            raise ConfigError("detector.box_noise_px", self.box_noise_px, "a number in [0, 100]")
        if not 0.0 <= _number("detector", "miss_p", self.miss_p) <= 1.0:
            raise ConfigError("detector.miss_p", self.miss_p, "a probability in [0, 1]")
        if not 0.0 <= _number("detector", "false_positives", self.false_positives) <= 100.0:
            raise ConfigError("detector.false_positives", self.false_positives, "a number in [0, 100]")
        for name in (
            "red_hue_max",
            "red_hue_min_wrap",
            "min_saturation",
            "min_value",
            "min_chroma",
            "extend_hue_max",
        ):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or not 0 <= v <= 255:
                raise ConfigError(f"detector.{name}", v, "an integer in [0, 255]")
        _positive_int("detector", "min_area_px", self.min_area_px)
        _positive_int("detector", "min_boundary_points", self.min_boundary_points)
        _positive("detector", "outlier_px", self.outlier_px)
        limits = self.ripe_hue_limits()
        known = isinstance(self.ripe_class, str) and self.ripe_class in limits
        if self.ripe_class is not None and not known:
            raise ConfigError("detector.ripe_class", self.ripe_class, "one of " + ", ".join(limits))
        _open_interval("detector", "max_outside_share", self.max_outside_share, 0.0, 1.0, "a share in (0, 1)")
        _positive("detector", "corner_px", self.corner_px)
        _positive_int("detector", "junction_margin", self.junction_margin)
        _positive("detector", "arc_tol_px", self.arc_tol_px)
        _non_negative("detector", "interior_edge", self.interior_edge)
        _open_interval("detector", "min_arc_deg", self.min_arc_deg, 0.0, 360.0, "a number in (0, 360)")
        _positive("detector", "max_fit_rms_px", self.max_fit_rms_px)
        _positive("detector", "max_fit_sigma_px", self.max_fit_sigma_px)
        _non_negative("detector", "min_radius_px", self.min_radius_px)
        _positive("detector", "size_tolerance_rel", self.size_tolerance_rel)
        if isinstance(self.ambiguity_ratio, bool) or not (
            isinstance(self.ambiguity_ratio, (int, float)) and 1.0 < self.ambiguity_ratio < math.inf
        ):
            raise ConfigError("detector.ambiguity_ratio", self.ambiguity_ratio, "a finite number > 1")

    @property
    def ripe_hue_max(self) -> int:
        """The hue limit of ripe pixels: that of ``ripe_class``, else ``red_hue_max``."""
        return self.red_hue_max if self.ripe_class is None else self.ripe_hue_limits()[self.ripe_class]


@dataclass(frozen=True, kw_only=True)
class FaultConfig:
    """Injected faults (all off by default), drawn per view from the episode's fault stream.

    For robustness studies: the fault-injection suite runs hundreds of seeded episodes with
    these on and checks that every one ends cleanly, within limits and with a bounded error.
    """

    drop_p: float = field(default=0.0, metadata=_why("a view's detection is lost (fruit hidden)"))
    hidden_views: tuple[int, ...] = field(
        default=(), metadata=_why("views whose detection is always lost (0 = the start view)")
    )
    false_p: float = field(
        default=0.0,
        metadata=_why("a view measures another red object 5-30 cm from the fruit (second blob, red leaf)"),
    )
    outlier_p: float = field(
        default=0.0, metadata=_why("a view's measurement gets a gross error (10-50 sigma)")
    )
    ik_failure_p: float = field(default=0.0, metadata=_why("a move's IK fails: the arm must hold"))
    planner_failure_p: float = field(
        default=0.0, metadata=_why("a plan's optimiser fails (raises): the episode must fall back")
    )

    def __post_init__(self) -> None:
        for name in ("drop_p", "false_p", "outlier_p", "ik_failure_p", "planner_failure_p"):
            v = _number("faults", name, getattr(self, name))
            if not 0.0 <= v <= 1.0:
                raise ConfigError(f"faults.{name}", getattr(self, name), "a probability in [0, 1]")
        views = self.hidden_views
        if isinstance(views, (str, bytes)) or not isinstance(views, (tuple, list)):
            raise ConfigError("faults.hidden_views", views, "a list of view numbers >= 0")
        for v in views:
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
                raise ConfigError("faults.hidden_views", views, "a list of view numbers >= 0")
        object.__setattr__(self, "hidden_views", tuple(int(v) for v in views))
        if self.false_p + self.outlier_p > 1.0:
            raise ConfigError("faults.false_p", self.false_p, "false_p + outlier_p <= 1")

    @property
    def any(self) -> bool:
        return bool(
            self.drop_p or self.hidden_views or self.false_p or self.outlier_p
            or self.ik_failure_p or self.planner_failure_p
        )  # fmt: skip


@dataclass(frozen=True, kw_only=True)
class EpisodeConfig:
    """A closed-loop MuJoCo episode: experiment, prior, stopping rules, approach mode.

    The constraints and the gate it runs with are those sections' own settings, which the
    MuJoCo world's preset adapts to the arm where they are unset (:mod:`bve_mj.config.presets`);
    ``[episode] band_distance_m``, ``band_tolerance_m``, ``step_m`` and ``gate_probability``
    are read there, with a :class:`DeprecationWarning` (:data:`bve_mj.config.moved.MOVED_KEYS`).
    """

    experiment: str = field(default="E5", metadata=_why("constraint set and loss (E5: all of the paper's)"))
    views: int = field(default=15, metadata=_why("most planned views after the first"))
    prior: PriorKind = field(
        default="detection",
        metadata=_why(
            "how the prior is made. detection: the target picked in a first image from the ready pose "
            "(which looks at a coarse guess, fruit + U[-e, e]^3): the prior mean lies on the ray to "
            "the fruit, its range off by U[-e, e] and its bearing by U[-l, l] each way "
            "(l = initial_lateral_error_m), the covariance elongated to match. cube: the paper's "
            "protocol, mean = fruit + U[-e, e]^3, isotropic; in a truss of touching fruit 5 cm apart "
            "it does not say which fruit is meant (episodes end ambiguous)"
        ),
    )
    initial_error_m: float = field(
        default=0.05,
        metadata=_why(
            "e: the prior's range error (detection) or error per axis (cube), at most: a fruit "
            "localised beyond it is not the target (the episode ends ambiguous)",
            "m",
        ),
    )
    initial_lateral_error_m: float | None = field(
        default=None,
        metadata=_why(
            "l: the detection prior's error across the ray, each way (a first detection's bearing). "
            "Unset: a third of the fruit type's mean radius (the first detection's ray passes "
            "through the fruit it picked, near its centre; a bearing error as wide as a cherry "
            "would not say which cherry is meant)",
            "m",
        ),
    )
    stop_sigma_m: float = field(
        default=0.0015, metadata=_why("stop when the largest posterior std falls below this", "m")
    )
    converge_after: int = field(
        default=3,
        metadata=_why(
            "converged needs at least this many accepted measurements since the last belief reset: two "
            "views triangulate a fruit, but a neighbour measured in one of them is then still "
            "consistent with the other (seen in truss_cluster: 18 mm off, claiming 1.4 mm); a third "
            "from elsewhere tells"
        ),
    )
    converge_redundant: bool = field(
        default=True,
        metadata=_why(
            "converged also needs the claim's largest std below stop_sigma_m with any one accepted "
            "measurement since the last reset left out: the answer rests on no single view (seen in "
            "truss_cluster: 9.0 mm off claiming 0.77 mm, 5.1 mm without the one view from above)"
        ),
    )
    agree_views: int = field(
        default=1,
        metadata=_why(
            "converged and stable also need, after the last accepted measurement that disputed the belief"
            " (NIS beyond the 99.9% chi-square quantile), this many accepted views from directions 30 deg"
            " or more away from it (independent errors) that agreed: the dispute says one of the two is "
            "off by more than the noise allows, and only an independent view settles which (seen in "
            "truss_cluster: 4.3 mm off claiming 0.9 mm after a dispute at NIS 24 that views from the same"
            " side 'confirmed'); 0 = no such check"
        ),
    )
    stop_stable_m: float = field(
        default=0.0003, metadata=_why("stop when the estimate moves less than this ...", "m")
    )
    stable_views: int = field(default=3, metadata=_why("... over this many views"))
    stall_m: float = field(
        default=0.005,
        metadata=_why(
            "stop when the camera moved less than this over stable_views views: the planner finds "
            "no better reachable view, and repeating one view fuses the same bias again "
            "(outcome stalled, or approach_blocked in approach mode)",
            "m",
        ),
    )
    stall_escapes: int = field(
        default=2,
        metadata=_why(
            "when the camera stalls (stall_m) and the planner learns from failed views, it is told the "
            "view it holds at is spent and the episode goes on, up to this many times, before a stall "
            "ends it: the planner's optimum near here fuses the same errors again, and a view from "
            "elsewhere adds what they lack (range-only trusses, where most episodes stalled: lower "
            "median errors for a sixth more views); 0 = a stall ends the episode"
        ),
    )
    approach: bool = field(default=False, metadata=_why("approach mode: eq. 13 term on, no band"))
    approach_distance_m: float = field(
        default=0.10, metadata=_why("approach ends with the camera this close to the estimate", "m")
    )
    approach_wall_distance_m: float = field(
        default=0.04,
        metadata=_why(
            "approach mode's plant wall, in front of the fruit centre: the paper's 0.1 m would keep "
            "the camera at >= 0.1 m; the row itself stands behind the fruit",
            "m",
        ),
    )

    def __post_init__(self) -> None:
        _positive_int("episode", "views", self.views, 10_000)
        _positive_int("episode", "stable_views", self.stable_views, 100)
        _positive_int("episode", "converge_after", self.converge_after, 100)
        for name in ("agree_views", "stall_escapes"):
            n = getattr(self, name)
            if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or not 0 <= n <= 100:
                raise ConfigError(f"episode.{name}", n, "an integer in [0, 100]")
        for f in ("stop_sigma_m", "approach_distance_m"):
            _positive("episode", f, getattr(self, f))
        _non_negative("episode", "initial_error_m", self.initial_error_m)
        if self.initial_lateral_error_m is not None:
            _non_negative("episode", "initial_lateral_error_m", self.initial_lateral_error_m)
        _choice("episode", "prior", self.prior, PriorKind)
        _non_negative("episode", "stop_stable_m", self.stop_stable_m)
        _non_negative("episode", "stall_m", self.stall_m)
        _non_negative("episode", "approach_wall_distance_m", self.approach_wall_distance_m)
        if not isinstance(self.converge_redundant, bool):
            raise ConfigError("episode.converge_redundant", self.converge_redundant, "true or false")
        if not isinstance(self.approach, bool):
            raise ConfigError("episode.approach", self.approach, "true or false")
        if not isinstance(self.experiment, str) or self.experiment.upper() not in EXPERIMENTS:
            raise ConfigError("episode.experiment", self.experiment, "one of " + ", ".join(EXPERIMENTS))

    def lateral_error_m(self, fruit_radius_m: float) -> float:
        """l: ``initial_lateral_error_m``, or a third of ``fruit_radius_m`` when unset."""
        if self.initial_lateral_error_m is not None:
            return float(self.initial_lateral_error_m)
        return fruit_radius_m / 3.0
