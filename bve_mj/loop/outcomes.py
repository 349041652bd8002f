"""How an episode ends: its outcome, whether it localised the fruit, and what each means."""

from __future__ import annotations

from enum import StrEnum

__all__ = ["Outcome"]


class Outcome(StrEnum):
    """How an episode ended. A ``str``: it compares equal to, and serialises as, its value
    (``Outcome.CONVERGED == "converged"``), so logs and JSON read as before."""

    CONVERGED = "converged"
    """The largest posterior standard deviation fell below the stop threshold."""
    STABLE = "stable"
    """The estimate stopped moving over accepted views."""
    APPROACHED = "approached"
    """Approach mode: the camera came close to the estimate."""
    MAX_VIEWS = "max_views"
    """The view budget ran out first."""
    STALLED = "stalled"
    """The camera stopped moving: the planner found no better view it can reach."""
    APPROACH_BLOCKED = "approach_blocked"
    """Approach mode: the arm could not bring the camera closer."""
    UNRELIABLE = "unreliable"
    """The final estimate is not supported by the measurements."""
    NEVER_DETECTED = "never_detected"
    """No view detected the fruit."""
    AMBIGUOUS = "ambiguous"
    """No view told the target apart from a neighbour (nothing measured, a fruit localised
    that fits the prior no better than another one seen, or one outside the prior's declared
    bound: a neighbour, not the target)."""
    UNREACHABLE = "unreachable"
    """The arm cannot reach a pose that looks at the fruit."""
    INCOMPLETE = "incomplete"
    """Every fruit: every track is localised, but a fruit seen once was never seen again from
    the views planned for it (its track was dropped)."""

    @property
    def success(self) -> bool:
        """A stop rule says the estimate is done (a claim the scenario suite holds it to)."""
        return self in (Outcome.CONVERGED, Outcome.STABLE, Outcome.APPROACHED)

    @property
    def localised(self) -> bool:
        """False when the fruit was out of reach, never seen (or never told apart from its
        neighbours), its estimate is not supported by the measurements, or (approach mode) the
        camera could not come close: ``bve-mj episode`` then exits 3."""
        return self not in (
            Outcome.UNREACHABLE, Outcome.NEVER_DETECTED, Outcome.AMBIGUOUS, Outcome.UNRELIABLE,
            Outcome.APPROACH_BLOCKED, Outcome.INCOMPLETE,
        )  # fmt: skip

    @property
    def note(self) -> str | None:
        """What the outcome means for the user, printed under an episode's summary (None for
        the plain ones)."""
        return _NOTES.get(self)


_NOTES = {
    Outcome.UNREACHABLE: "the arm cannot reach a pose that looks at the fruit's estimate: nothing was "
    "measured",
    Outcome.NEVER_DETECTED: "no view detected the fruit: the estimate is the prior",
    Outcome.AMBIGUOUS: "more than one fruit in view fits the estimate about equally well, and no view "
    "told which one is the target: the estimate is the prior, a fruit that fits the prior no "
    "better than another one seen (maybe not the target), or a fruit outside the prior's declared "
    "error bound (episode.initial_error_m: not the target, which the views may not have shown)",
    Outcome.APPROACH_BLOCKED: "the arm found no reachable pose closer to the fruit (the camera stopped "
    "moving): the fruit is localised but not approached",
    Outcome.UNRELIABLE: "the final estimate is not supported by the measurements (fewer than two "
    "accepted since the last reset, most recent ones gated out as disagreeing with it, or views it "
    "gated out supporting another answer as well): do not trust it",
    Outcome.INCOMPLETE: "every fruit tracked is localised, but the zone holds a fruit that is not: "
    "something seen once (a fruit the detector refused from every later view, or a false "
    "detection) was never seen again, a fruit was seen only in part, from several views, and "
    "never measured (seen_in_part in the JSON), or part of the zone was never in an image: the arm "
    "could not frame it (zone_framed in the JSON: the share that was)",
    Outcome.STALLED: "the camera stopped moving (no better reachable view): more views would only "
    "repeat the same measurement",
}
