"""Settings of the injected faults and the closed-loop episode."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from bve_mj.config.experiments import EXPERIMENTS
from bve_mj.config.fields import (
    PriorKind,
    _choice,
    _non_negative,
    _number,
    _positive,
    _positive_int,
    _why,
)
from bve_mj.errors import ConfigError

__all__ = ["EpisodeConfig", "FaultConfig"]


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
