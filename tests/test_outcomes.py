"""Typed outcomes and events: what they mean, and that they read as their text in logs."""

import json

import pytest

from bve_mj.loop.events import Event
from bve_mj.loop.outcomes import Outcome


def test_outcomes_read_as_their_text_and_say_what_they_mean():
    assert Outcome.CONVERGED == "converged" and json.dumps({"o": Outcome.STALLED}) == '{"o": "stalled"}'
    assert {o for o in Outcome if o.success} == {Outcome.CONVERGED, Outcome.STABLE, Outcome.APPROACHED}
    not_localised = {o for o in Outcome if not o.localised}
    assert not_localised == {
        "unreachable",
        "never_detected",
        "ambiguous",
        "unreliable",
        "approach_blocked",
        "incomplete",
    }
    assert not any(o.success for o in not_localised)
    assert Outcome.UNRELIABLE.note and "do not trust" in Outcome.UNRELIABLE.note
    assert Outcome.CONVERGED.note is None
    with pytest.raises(ValueError):
        Outcome("done")


def test_events_carry_a_known_kind_and_their_reason():
    e = Event("planner_failed", "ValueError: singular")
    assert e.kind == "planner_failed" and str(e) == "planner_failed: ValueError: singular"
    assert str(Event("belief_reset")) == "belief_reset"
    with pytest.raises(ValueError, match="not one of"):
        Event("exploded")  # type: ignore[arg-type]
