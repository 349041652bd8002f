"""What happened at a view beside the measurement: failures, how they were handled, injected
faults. Typed: a kind from a fixed list and an optional detail (the reason)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, get_args

__all__ = ["Event", "EventKind"]

EventKind = Literal[
    "planner_failed",  # the planner raised or returned a non-finite view: the camera held
    "ik_failed",  # the arm's IK found no joint angles for the planned view: the arm held
    "belief_reset",  # gated-out measurements that agree with each other replaced the belief
    "ambiguous",  # the detector saw more than one fruit fitting the estimate and measured none
    "dropped",  # injected: the view's detection was lost
    "false_detection",  # injected: the view measured another red object
    "outlier",  # injected: the measurement got a gross error
    "ik_failure",  # injected: the move's IK failed
    "seen_in_part_reset",  # --fruits all: weak evidence of fruit seen in part broke a belief: restarted
    "seen_in_part_settled",  # --fruits all: a fruit seen in part proved a measured track's: forgotten
    "zone_unframed",  # --fruits all: a view aimed at a part of the zone not yet framed framed none of it
    "retreated",  # --fruits all: the planner found no view, and the camera drew back towards the aisle
    "unhiding",  # --fruits all: the fruit's BVE view would not show it; this view, which should, was taken
    "stall_escaped",  # the camera had stalled: the planner was told that view is spent, and planned this one
    "outside_prior_bound",  # the fruit localised lies outside the prior's declared bound: not the target
]


@dataclass(frozen=True)
class Event:
    """One event of a view: its kind and, where there is one, the reason."""

    kind: EventKind
    detail: str = ""

    def __post_init__(self) -> None:
        if self.kind not in get_args(EventKind):
            raise ValueError(f"event kind {self.kind!r}: not one of {', '.join(get_args(EventKind))}")

    def __str__(self) -> str:
        return f"{self.kind}: {self.detail}" if self.detail else self.kind
