"""What an episode leaves: a record per view and the finished episode."""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from bve_mj.estimation import Belief
from bve_mj.estimation.claim_shape import GAUSSIAN, ClaimShape
from bve_mj.loop.events import Event, EventKind
from bve_mj.loop.outcomes import Outcome
from bve_mj.planning.plan import PlanStatus

__all__ = ["EpisodeResult", "ViewRecord", "since_reset"]


@dataclass(frozen=True)
class ViewRecord:
    """One view: where the camera was, what the planner said, what the filter made of it.

    ``iteration`` 0 is the view from the start pose (no plan: status None). ``events``: what
    went wrong and how it was handled (:class:`~bve_mj.loop.events.Event`: ``planner_failed``
    with its reason, ``ik_failed``, ``belief_reset``, ``ambiguous``, ``outside_prior_bound`` on
    the last view of an episode whose fruit lies outside the prior's bound, and injected faults:
    ``dropped``, ``false_detection``, ``outlier``, ``ik_failure``). ``belief`` is what the
    episode claims; ``filter_belief`` the filter's own, where the claim differs from it
    (:class:`~bve_mj.loop.claims.Claims`: the fruit's own offset, the innovation, refusal and
    tail scales), else None. Where the claim has a heavy-tailed shape (:class:`~bve_mj.
    estimation.claim_shape.ClaimShape`, :attr:`EpisodeResult.shape`) ``belief`` is its
    bound, the Gaussian the loop decides with; :meth:`EpisodeResult.claim` is the claim.
    ``sensor_cov``: the share of ``belief``'s covariance the declared sensor errors make (the
    calibration biases' prior, encoder noise: :mod:`bve_mj.estimation.sensor_share`), as the
    bound holds it (:meth:`~bve_mj.loop.claims.Claims.sensor_part`), which the claim keeps
    whole; None where there is none.
    """

    iteration: int
    p_world_camera: np.ndarray
    plan_status: PlanStatus | None
    plan_feasible: bool
    plan_s: float
    measured: bool
    accepted: bool
    nis: float
    belief: Belief
    world: dict[str, object] | None = None
    events: tuple[Event, ...] = ()
    filter_belief: Belief | None = None
    sensor_cov: np.ndarray | None = None

    def has(self, kind: EventKind) -> bool:
        """Whether an event of this kind happened at this view."""
        return any(e.kind == kind for e in self.events)


def since_reset(views: Sequence[ViewRecord]) -> Sequence[ViewRecord]:
    """The views since the last belief reset, the reset's own view first (all without one)."""
    return views[max((k for k, v in enumerate(views) if v.has("belief_reset")), default=0) :]


@dataclass(frozen=True)
class EpisodeResult:
    """A finished episode: the prior, every view, the final belief, and the wall time [s].

    ``shape``: the shape of what its views claim (Gaussian unless the episode's claims say
    otherwise): each view's ``belief`` is the claim's bound, and :meth:`claim` the claim
    itself, the bound's covariance over ``shape.bound_scale`` (the errors' second moment)."""

    prior: Belief
    views: tuple[ViewRecord, ...]
    wall_s: float
    outcome: Outcome = Outcome.MAX_VIEWS
    shape: ClaimShape = GAUSSIAN

    @property
    def final(self) -> Belief:
        """The final claim's bound (the belief the loop decided with)."""
        return self.views[-1].belief if self.views else self.prior

    @property
    def final_claim(self) -> Belief:
        """The final claim: its mean and covariance (:attr:`final` where it is Gaussian)."""
        return self.claim(self.views[-1]) if self.views else self.prior

    def claim(self, view: ViewRecord) -> Belief:
        """What ``view`` claims: its bound's mean, with the covariance of the claim's shape."""
        return self.shape.claim(view.belief, view.sensor_cov)

    @property
    def final_filter(self) -> Belief:
        """The filter's own final belief (:attr:`final` where the episode claims no more)."""
        last = self.views[-1] if self.views else None
        if last is None:
            return self.prior
        return last.belief if last.filter_belief is None else last.filter_belief

    def event_counts(self) -> dict[str, int]:
        """How often each kind of event happened, over all views."""
        return dict(Counter(e.kind for v in self.views for e in v.events))
