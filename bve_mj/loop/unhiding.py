"""The arm's view of a hidden fruit: :func:`~bve_mj.planning.unhide.unhiding_positions`
reached by look-at IK, for the every-fruit planner's ``unhide``."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from bve_mj.config import Settings
from bve_mj.planning.constraints import ConstraintName, build_constraints
from bve_mj.planning.every_fruit import FruitTarget
from bve_mj.planning.plan import ViewPlan
from bve_mj.planning.unhide import ShownFn, UnhideOptions, unhiding_positions
from bve_mj.robot import IkOptions, look_at_ik
from bve_mj.robot.kinematics import ArmKinematics

__all__ = ["ArmUnhider"]


@dataclass
class ArmUnhider:
    """``unhide(fruit, fruits, p_world_camera, q)``: the best-ranked position from which the
    tracks predict ``fruit``'s outline shows (every fruit in ``fruits`` counted as a
    possible cover) that the arm reaches from ``q``, looking at the fruit's estimate; None
    where none of the ranked positions is reached.

    Args:
        settings: the episode's search settings (task constraints, step, distance band).
        constraint_names: the task constraints a view must satisfy.
        kin: the arm.
        shown: a fruit's predicted outline from camera positions looking at it [deg].
        min_arc_deg: the outline the detector needs.
        rng: the draws and the IK's restarts.
        upright: solve the IK with the image upright.
        q_start: the arm's joint angles at the start. Each call's ``q`` (the encoders' last
            reading) replaces them; a call without one (after a move whose IK failed) starts
            from the last given, as the BVE's own planners do.
        ik_restarts: random restarts of the look-at IK where the start from ``q`` fails; 0
            by default: in 9 every-fruit episodes of three truss scenes (seed 9292), 24 of the
            25 views found came from the start at ``q``, and two restarts a position were two
            thirds of the time the IK spent on positions it could not reach (~12 ms each);
            a restart's answer is also a far reconfiguration of the arm. The start from ``q``
            runs at most 40 iterations, as a plan's does (those 25 took at most 20; a position
            out of reach ran all 100).
    """

    settings: Settings
    constraint_names: Sequence[ConstraintName]
    kin: ArmKinematics
    shown: ShownFn
    min_arc_deg: float
    rng: np.random.Generator
    upright: bool
    q_start: np.ndarray
    options: UnhideOptions = field(default_factory=UnhideOptions)
    ik_restarts: int = 0

    def __post_init__(self) -> None:
        if (
            isinstance(self.ik_restarts, bool)
            or not isinstance(self.ik_restarts, int)
            or self.ik_restarts < 0
        ):
            raise ValueError(f"ArmUnhider.ik_restarts must be an integer >= 0, got {self.ik_restarts!r}")
        self._q = np.asarray(self.q_start, dtype=float).copy()

    def __call__(
        self,
        fruit: FruitTarget,
        fruits: Sequence[FruitTarget],
        p_world_camera: np.ndarray,
        q: np.ndarray | None,
    ) -> ViewPlan | None:
        ids = [f.id for f in fruits]
        if fruit.id not in ids:
            raise ValueError(f"fruit {fruit.id} is not among the fruit given")
        k_hat = fruit.belief.centre_m
        centres = np.array([f.belief.centre_m for f in fruits])
        radii = np.array([f.belief.radius_m or self.settings.fruit.radius_m for f in fruits])
        ranked = unhiding_positions(
            ids.index(fruit.id), centres, radii, p_world_camera,
            build_constraints(self.constraint_names, self.settings, k_hat),
            self.settings.step_m, self.settings.band_distance_m, self.shown, self.min_arc_deg,
            self.rng, self.options,
        )  # fmt: skip
        if q is not None:
            self._q = np.asarray(q, dtype=float).copy()
        q_now = self._q
        ik_options = IkOptions(restarts=self.ik_restarts, max_iterations=40, upright=self.upright)
        for p, _ in ranked:
            ik = look_at_ik(self.kin, p, k_hat, q_now, self.rng, ik_options)
            if ik.success:
                return ViewPlan(p, k_hat.copy(), "optimal", True, 0.0, q=ik.q)
        return None
