"""How an episode ends: the outcomes, which of them did not localise the fruit, what each means."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    pass


NOT_LOCALISED = ("unreachable", "never_detected", "ambiguous", "unreliable", "approach_blocked")

"""Episode outcomes that exit 3: the fruit was out of the arm's reach, never seen (or never told
apart from its neighbours), its estimate is not supported by the measurements, or (approach
mode) the arm could not bring the camera close."""


OUTCOME_NOTES = {
    "unreachable": "the arm cannot reach a pose that looks at the fruit's estimate: nothing was measured",
    "never_detected": "no view detected the fruit: the estimate is the prior",
    "ambiguous": "more than one fruit in view fits the estimate about equally well, and no view told "
    "which one is the target: nothing was measured, the estimate is the prior",
    "approach_blocked": "the arm found no reachable pose closer to the fruit (the camera stopped "
    "moving): the fruit is localised but not approached",
    "unreliable": "the final estimate is not supported by the measurements (fewer than two "
    "accepted since the last reset, or most recent ones gated out as disagreeing with it): do not "
    "trust it",
    "stalled": "the camera stopped moving (no better reachable view): more views would only repeat "
    "the same measurement",
}

"""What an outcome means, printed under the episode's summary."""
