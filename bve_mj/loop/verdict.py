"""Whether an episode's final estimate is what its views say: the checks an outcome must pass
before it stands (:meth:`bve_mj.loop.episode.EpisodeLoop.finish`): the measurements it gated
out hold no second answer, and the fruit it localised is the one the prior meant (inside the
prior's declared bound, and no other fruit seen that the prior prefers)."""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence

import numpy as np

from bve_mj.estimation import Belief, UpdateResult
from bve_mj.estimation.metrics import chi2_quantile
from bve_mj.estimation.prior_bound import OUTSIDE_Z, PriorBound
from bve_mj.loop.events import Event
from bve_mj.loop.records import ViewRecord
from bve_mj.sim.world import Observation

__all__ = ["another_fruit_fits_the_prior", "contested", "outside_prior_bound", "second_answer"]


def contested(
    prior: Belief,
    final: Belief,
    rejected: Sequence[Observation],
    gate: float | None,
    update: Callable[..., UpdateResult],
) -> bool:
    """Whether the gated-out measurements hold a second answer: two of them that the final
    belief still rejects but that agree with each other and with the prior (fused one after
    the other from the prior, both pass the gate). The views then saw the fruit in two
    places (the accepted ones may be the wrong pair: a biased silhouette fused early gates
    out the right views that follow), and the final estimate is not what the evidence says."""
    if gate is None:
        return False
    left = [obs for obs in rejected if not update(final, obs.z, obs.model, gate).accepted]
    for a, b in itertools.combinations(left, 2):
        first = update(prior, a.z, a.model, gate)
        if first.accepted and update(first.belief, b.z, b.model, gate).accepted:
            return True
    return False


def second_answer(
    prior: Belief,
    final: Belief,
    claimed: Belief,
    accepted: Sequence[Observation],
    rejected: Sequence[Observation],
    gate: float | None,
    update: Callable[..., UpdateResult],
) -> bool:
    """Whether a gated-out measurement, with the accepted ones that agree with it, makes a
    second answer as well supported as the final one, and one the episode's claim all but
    excludes: from the prior, the rejected measurement (one the final belief still rejects,
    plausible under the prior) and then each accepted one in turn through the gate, the
    second belief fuses at least as many measurements as the final one, and its centre lies
    outside the 99% ellipsoid the episode claims (``claimed``). The views then do not say
    which answer is right, while the claim says the other one is all but impossible.

    Seen in ``cherry_truss`` of seed 6161, episode 3164729239: one early silhouette several σ
    off (a heavy tail of the detector) fused first gated out the best view after it (260° of
    outline), and the views that followed agreed with both; views 1, 3 and 4 converged 1.8 mm
    off claiming σmax 0.44 mm (NEES 23.5), views 2, 3 and 4 agree as well, 1.5 mm away (15.2
    in the claim's χ²(3): outside its 99%, inside its 99.9% ellipsoid). Two correct episodes of
    that seed had such a second answer 0.5 mm away, inside the claim (2.0 and 4.2): covered by
    it. A neighbour's measurement makes no second answer: the accepted views of the target do
    not pass the gate beside it."""
    if gate is None or not accepted:
        return False
    f = claimed.position
    excluded = float(chi2_quantile(0.99, 3))
    for r in rejected:
        if update(final, r.z, r.model, gate).accepted:
            continue
        first = update(prior, r.z, r.model, gate)
        if not first.accepted:
            continue
        belief, support = first.belief, 1
        for obs in accepted:
            result = update(belief, obs.z, obs.model, gate)
            if result.accepted:
                belief, support = result.belief, support + 1
        d = belief.position.mean - f.mean
        if support >= len(accepted) and float(d @ np.linalg.solve(f.cov, d)) > excluded:
            return True
    return False


def outside_prior_bound(bound: PriorBound | None, claimed: Belief) -> Event | None:
    """The event ``outside_prior_bound`` when the claimed centre lies outside the box the
    prior's error is declared to stay in by more than :data:`OUTSIDE_Z` of its own σ on one
    of the box's axes (:class:`PriorBound`: a neighbour, not the target the prior meant);
    None inside it, or without a bound."""
    if bound is None:
        return None
    excess = bound.excess_sigmas(claimed)
    if excess <= OUTSIDE_Z:
        return None
    return Event("outside_prior_bound", f"{excess:.1f} sigma beyond the prior's declared error bound")


def another_fruit_fits_the_prior(
    prior: Belief, final: Belief, views: Sequence[ViewRecord], odds: float
) -> bool:
    """Whether a view found two fruit the estimate allowed (``ambiguous_candidates`` in its
    world info: their rough centres, distinct fruit) and the prior finds one of them, another
    fruit than the one localised, at least ``odds`` times as likely to be the target.

    The prior is all that says which fruit is the target (seen in ``cherry_truss``: the
    target hidden from every view but the ambiguous ones, the neighbour on the prior's ray
    localised instead, 16 mm off, claiming 1.4 mm). The likelihood that a fruit is the
    target is the prior's density at it, with the fruit's own uncertainty:
    N(x; prior mean, prior cov + cov(x)), the final belief for the fruit localised, the
    rough centre (range from size: long along the ray) for the other. A rough centre is
    penalised by its spread (the determinant), not only favoured by it (a smaller
    Mahalanobis distance): comparing Mahalanobis distances alone ended correct episodes
    ``ambiguous`` 12 times in 280 (held-out seed 6161).

    Only views before the first accepted measurement count: until then the prior alone said
    which fruit was meant; after it, the belief did (an ambiguous view 5 cm from a localised
    fruit is a refusal, not a second fruit the prior allows). The fruit localised is the
    candidate nearest the final estimate (Mahalanobis), if within its χ²(3) 0.999 gate."""
    p0, f = prior.position, final.position
    log_final = _log_density(f.mean, p0.mean, p0.cov + f.cov)
    threshold, same_fruit = math.log(odds), float(chi2_quantile(0.999, 3))
    for v in views:
        if v.accepted:  # the fruit was chosen: later ambiguous views refused a measurement of it
            break
        found = (v.world or {}).get("ambiguous_candidates", ())
        rough = [
            (np.asarray(c["p_world_m"], dtype=float), np.asarray(c["cov_world_m2"], dtype=float))
            for c in found  # type: ignore[attr-defined]
        ]
        if not rough:
            continue
        to_final = [float((c - f.mean) @ np.linalg.solve(C + f.cov, c - f.mean)) for c, C in rough]
        localised = int(np.argmin(to_final)) if min(to_final) <= same_fruit else -1
        for i, (c, C) in enumerate(rough):
            if i != localised and _log_density(c, p0.mean, p0.cov + C) - log_final >= threshold:
                return True
    return False


def _log_density(x: np.ndarray, mean: np.ndarray, cov: np.ndarray) -> float:
    """ln N(x; mean, cov)."""
    d = x - mean
    return -0.5 * float(d @ np.linalg.solve(cov, d) + np.linalg.slogdet(2.0 * np.pi * cov)[1])
