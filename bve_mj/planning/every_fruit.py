"""The next view for every fruit of a truss at once: the BVE's views for the least localised
fruit, scored by the information they give all of them.

Per view, the BVE (with every constraint and, in the closed loop, the arm's kinematics) plans
a viewpoint for each of the ``candidates`` fruit whose claimed σmax is largest, each with its
own planner (which remembers that fruit's failed and fused views). Each candidate viewpoint
is then scored by the joint information it gives the fruit not yet localised,

    J(c) = Σ_i [ln det P_i - ln det (P_i⁻¹ + H_iᵀ R_i⁻¹ H_i)⁻¹]_centre   over fruit i seen from c,

the sum over fruit of the log-volume each one's centre uncertainty loses (the D-optimal
criterion, summed: −ln det of each fruit's position covariance after the view), counting
only the fruit the view is predicted to see (in the image, outline not hidden by another
fruit's: :mod:`bve_mj.estimation.visibility`), each fruit's term scaled down near the
directions from which a view predicted to show it did not measure it
(:meth:`EveryFruitPlanner.note_hidden`: the tracks are spheres, and the stems, leaves and
unripe fruit that hide a fruit are not in them). The highest J wins; a fruit hidden from every
candidate is left to later views. Why not optimise J itself: each fruit's BVE problem is
smooth and the arm's joint-space solver handles one look-at target; J over a truss is a sum
of terms switched on and off by occlusion, which a local optimiser cannot follow.

Where a candidate's BVE view would not see the fruit it was planned for (behind its
neighbours, as the tracks predict), ``unhide`` may offer a view from which it would
(:mod:`bve_mj.planning.unhide`); it stands in for that BVE view and is scored the same way.

The baselines (:class:`bve_mj.planning.fruit_baselines.PatternPlanner`: random, circle, three
fixed views) plan without the
tracks' information: one single-target baseline planner, under the same constraints and the
arm's reachability, aimed at the centre of the fruit found so far (the work zone's centre
before any), its views planned for no fruit in particular (``planned_for`` = :data:`EXPLORE`).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

from bve_mj.errors import BveError
from bve_mj.estimation.belief import Belief
from bve_mj.geometry import camera_rotation
from bve_mj.planning.plan import (
    LearnsFromFailedViews,
    LearnsFromFusedViews,
    Planner,
    SyncsToEncoders,
    ViewPlan,
)

__all__ = [
    "EXPLORE",
    "CandidateScore",
    "EveryFruitPlanner",
    "FruitTarget",
    "LearnsWhereFruitHide",
    "PlansForEveryFruit",
    "ReportsCandidates",
    "information_gain",
]

EXPLORE = -1
"""The planner key (and ``planned_for``) of the views that explore the work zone."""


@dataclass(frozen=True)
class FruitTarget:
    """A fruit as the planner sees it: its track id, the filter's belief (centre, radius),
    whether it is localised (its claimed σmax below the stop threshold), that σmax [m], the
    unit directions fruit → camera of the views fused (k, 3) and their cameras' positions [m]
    (k, 3; None: not known, the views counted by their directions alone)."""

    id: int
    belief: Belief
    localised: bool
    sigma_max_m: float
    directions: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    cameras: np.ndarray | None = None


@dataclass(frozen=True)
class CandidateScore:
    """One candidate viewpoint: planned for fruit ``planned_for``, its joint information J
    [nats] and the fruit it is predicted to see."""

    planned_for: int
    score: float
    sees: tuple[int, ...]
    status: str
    kind: str = "bve"
    """``bve``: the fruit's BVE view; ``unhide``: a view where the tracks predict the fruit's
    outline shows, taken instead of a BVE view that would not see it (``unhide`` above)."""


def information_gain(belief: Belief, H: np.ndarray, noise_cov: np.ndarray) -> float:
    """ln det P_c - ln det P'_c: how much the centre block of the covariance shrinks (in log
    volume) when a measurement with Jacobian ``H`` (m, n) and noise ``noise_cov`` is fused."""
    P = belief.cov
    info = np.linalg.solve(noise_cov, H)
    post = np.linalg.inv(np.linalg.inv(P) + H.T @ info)
    before = np.linalg.slogdet(P[:3, :3])[1]
    after = np.linalg.slogdet(post[:3, :3])[1]
    return float(before - after)


@runtime_checkable
class ReportsCandidates(Protocol):
    """A planner that keeps the scores of the candidates its last plan weighed."""

    last_scores: tuple[CandidateScore, ...]


@runtime_checkable
class PlansForEveryFruit(Protocol):
    """What the every-fruit loop asks of its planner."""

    def plan(
        self,
        fruits: Sequence[FruitTarget],
        p_world_camera: np.ndarray,
        iteration: int,
        q: np.ndarray | None = None,
    ) -> tuple[ViewPlan, int]: ...

    def explore(
        self, zone: Belief, p_world_camera: np.ndarray, iteration: int, q: np.ndarray | None = None
    ) -> ViewPlan: ...

    def forget(self, fruit: int) -> None: ...

    def set_configuration(self, q: np.ndarray) -> None: ...

    def note_failed_view(
        self, fruit: int, p_world_camera: np.ndarray, p_world_target: np.ndarray
    ) -> None: ...

    def note_fused_view(self, fruit: int, p_world_camera: np.ndarray, p_world_target: np.ndarray) -> None: ...

    def note_explored(self, p_world_camera: np.ndarray, p_world_target: np.ndarray) -> None: ...


@runtime_checkable
class LearnsWhereFruitHide(Protocol):
    """A planner told of each view the tracks predicted to show a fruit that did not measure
    it (:meth:`EveryFruitPlanner.note_hidden`)."""

    def note_hidden(self, fruit: int, p_world_camera: np.ndarray, p_world_fruit: np.ndarray) -> None: ...


HIDDEN_WIDTH = 1.0 - np.cos(np.radians(15.0))
"""How far a direction a fruit was hidden from reaches: a candidate view θ from it counts
exp(-(1 - cos θ) / this) less of the fruit's gain (half at 13°)."""


@dataclass
class EveryFruitPlanner:
    """Views for every fruit (see the module docstring).

    Args:
        make: a single-fruit planner for a new fruit (the BVE with the arm's kinematics).
        gain: ``gain(fruit, p_world_camera, R_world_camera)``: the information one fruit gets
            from a view (:func:`information_gain` of the measurement it would give).
        visible: ``visible(centres (n, 3), radii (n,), p_world_camera, R_world_camera)`` →
            (n,) bool: the fruit the view would see.
        candidates: how many of the least localised fruit get a planned viewpoint.
        clear: ``clear(plan)``: whether the move to a planned view keeps the arm clear of what
            the robot knows (the world's check, :func:`bve_mj.sim.arm_boxes.path_clearance`);
            a candidate whose move is not clear is left out as one whose planner failed, an
            exploring view likewise. None: not checked.
        unhide: ``unhide(fruit, fruits, p_world_camera, q)``: a view from which ``fruit`` would
            show its outline (:func:`bve_mj.planning.unhide.unhiding_positions`, reached by
            the arm), or None. Where a candidate's BVE view would not see the fruit it was
            planned for (or its planner failed), this view stands in for it, scored the same
            way. None: the BVE's views only.
    """

    make: Callable[[], Planner]
    gain: Callable[[FruitTarget, np.ndarray, np.ndarray], float]
    visible: Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], np.ndarray]
    candidates: int = 2
    clear: Callable[[ViewPlan], bool] | None = None
    unhide: (
        Callable[[FruitTarget, Sequence[FruitTarget], np.ndarray, np.ndarray | None], ViewPlan | None] | None
    ) = None
    _planners: dict[int, Planner] = field(default_factory=dict)
    _hidden: dict[int, list[np.ndarray]] = field(default_factory=dict)  # directions fruit → camera
    last_scores: tuple[CandidateScore, ...] = ()

    def planner(self, fruit: int) -> Planner:
        """The single-fruit planner of track ``fruit`` (made on first use)."""
        if fruit not in self._planners:
            self._planners[fruit] = self.make()
        return self._planners[fruit]

    def forget(self, fruit: int) -> None:
        """Track ``fruit`` is gone (deleted or merged)."""
        self._planners.pop(fruit, None)
        self._hidden.pop(fruit, None)

    def note_hidden(self, fruit: int, p_world_camera: np.ndarray, p_world_fruit: np.ndarray) -> None:
        """A view the tracks predicted to show ``fruit`` did not measure it: what hid it (a stem,
        a leaf, an unripe fruit) is not in the prediction, and views from near that direction
        are scored with less of its gain (:data:`HIDDEN_WIDTH`) until one measures it."""
        d = np.asarray(p_world_camera, dtype=float) - np.asarray(p_world_fruit, dtype=float)
        self._hidden.setdefault(fruit, []).append(d / max(float(np.linalg.norm(d)), 1e-9))

    def _shown(self, fruit: int, p_world_camera: np.ndarray, p_world_fruit: np.ndarray) -> float:
        """The share of ``fruit``'s gain a view from ``p_world_camera`` is counted with."""
        if not self._hidden.get(fruit):
            return 1.0
        d = p_world_camera - p_world_fruit
        cos = np.array(self._hidden[fruit]) @ (d / max(float(np.linalg.norm(d)), 1e-9))
        return 1.0 - float(np.exp(-(1.0 - cos.max()) / HIDDEN_WIDTH))

    def set_configuration(self, q: np.ndarray) -> None:
        """Every fruit's planner plans the next move from the encoders' ``q``."""
        for p in self._planners.values():
            if isinstance(p, SyncsToEncoders):
                p.set_configuration(q)

    def note_failed_view(self, fruit: int, p_world_camera: np.ndarray, p_world_target: np.ndarray) -> None:
        p = self._planners.get(fruit)
        if isinstance(p, LearnsFromFailedViews):
            p.note_failed_view(p_world_camera, p_world_target)

    def note_fused_view(self, fruit: int, p_world_camera: np.ndarray, p_world_target: np.ndarray) -> None:
        self._hidden.pop(fruit, None)  # measured again: what hid it was that view's
        p = self._planners.get(fruit)
        if isinstance(p, LearnsFromFusedViews):
            p.note_fused_view(p_world_camera, p_world_target)

    def explore(
        self, zone: Belief, p_world_camera: np.ndarray, iteration: int, q: np.ndarray | None = None
    ) -> ViewPlan:
        """A view of the work zone from a new direction: the BVE for the zone (a wide belief
        around its centre) with every view taken so far noted as a failed view of it
        (:meth:`note_explored`), so it looks where no view has.

        Raises:
            BveError: when the planner finds no viewpoint."""
        planner = self.planner(EXPLORE)
        if q is not None and isinstance(planner, SyncsToEncoders):
            planner.set_configuration(q)
        plan = planner.plan(zone, p_world_camera, iteration)
        if not (np.all(np.isfinite(plan.p_world_camera)) and np.all(np.isfinite(plan.p_world_target))):
            raise BveError("the exploration view is not finite")
        if self.clear is not None and not self.clear(plan):
            raise BveError("the move to the exploration view passes through a known fruit or the canopy")
        if q is not None:
            self.set_configuration(q)
        return plan

    def note_explored(self, p_world_camera: np.ndarray, p_world_target: np.ndarray) -> None:
        """A view of the zone was taken from ``p_world_camera``: exploration looks elsewhere."""
        p = self.planner(EXPLORE)
        if isinstance(p, LearnsFromFailedViews):
            p.note_failed_view(p_world_camera, p_world_target)

    def _bve_plan(
        self,
        target: FruitTarget,
        p_world_camera: np.ndarray,
        iteration: int,
        q: np.ndarray | None,
        failures: list[str],
    ) -> ViewPlan | None:
        """The BVE's view for ``target``, or None (the reason appended to ``failures``)."""
        planner = self.planner(target.id)
        if q is not None and isinstance(planner, SyncsToEncoders):
            planner.set_configuration(q)
        try:
            plan = planner.plan(target.belief, p_world_camera, iteration)
        except (BveError, ArithmeticError, ValueError, np.linalg.LinAlgError) as exc:
            failures.append(f"fruit {target.id}: {type(exc).__name__}: {exc}")
            return None
        if not (np.all(np.isfinite(plan.p_world_camera)) and np.all(np.isfinite(plan.p_world_target))):
            failures.append(f"fruit {target.id}: non-finite viewpoint")
            return None
        if self.clear is not None and not self.clear(plan):
            failures.append(f"fruit {target.id}: the move passes through a known fruit or the canopy")
            return None
        return plan

    def _sees(self, plan: ViewPlan, centres: np.ndarray, radii: np.ndarray) -> np.ndarray:
        R = camera_rotation(plan.p_world_camera, plan.p_world_target)
        return np.asarray(self.visible(centres, radii, plan.p_world_camera, R), dtype=bool)

    def plan(
        self,
        fruits: Sequence[FruitTarget],
        p_world_camera: np.ndarray,
        iteration: int,
        q: np.ndarray | None = None,
    ) -> tuple[ViewPlan, int]:
        """The next viewpoint and the fruit it was planned for.

        ``q``: the arm's joint angles now (each candidate's planner starts from them).

        Raises:
            BveError: when there is no fruit to plan for, or no candidate's planner succeeds.
        """
        t0 = time.perf_counter()
        open_ = [f for f in fruits if not f.localised]
        if not open_:
            raise BveError("every fruit is localised: nothing to plan for")
        chosen = sorted(open_, key=lambda f: -f.sigma_max_m)[: self.candidates]
        centres = np.array([f.belief.centre_m for f in fruits])
        radii = np.array([f.belief.radius_m or 0.0 for f in fruits])
        best: tuple[float, ViewPlan, int] | None = None
        scores: list[CandidateScore] = []
        failures: list[str] = []
        for target in chosen:
            plan = self._bve_plan(target, p_world_camera, iteration, q, failures)
            sees = None if plan is None else self._sees(plan, centres, radii)
            kind = "bve"
            if self.unhide is not None and (
                sees is None or not sees[[f.id for f in fruits].index(target.id)]
            ):
                shown = self.unhide(target, fruits, p_world_camera, q)
                if shown is not None and (self.clear is None or self.clear(shown)):
                    plan, sees, kind = shown, self._sees(shown, centres, radii), "unhide"
            if plan is None or sees is None:
                continue
            R = camera_rotation(plan.p_world_camera, plan.p_world_target)
            score = sum(
                self.gain(f, plan.p_world_camera, R)
                * self._shown(f.id, plan.p_world_camera, f.belief.centre_m)
                for f, s in zip(fruits, sees, strict=True)
                if s and not f.localised
            )
            if not plan.feasible:
                score -= 1e3  # a plan that breaks a constraint only when nothing else is left
            scores.append(
                CandidateScore(
                    target.id,
                    float(score),
                    tuple(f.id for f, s in zip(fruits, sees, strict=True) if s),
                    plan.status,
                    kind,
                )
            )
            if best is None or score > best[0]:
                best = (score, plan, target.id)
        self.last_scores = tuple(scores)
        if best is None:
            raise BveError("no fruit's planner found a viewpoint: " + "; ".join(failures))
        _, plan, fruit = best
        if q is not None:
            self.set_configuration(q)  # the candidates' planners moved their arm state
        plan_s = time.perf_counter() - t0
        return ViewPlan(
            plan.p_world_camera, plan.p_world_target, plan.status, plan.feasible, plan.max_violation,
            plan.loss, plan.iterations, plan_s, plan.q,
        ), fruit  # fmt: skip
