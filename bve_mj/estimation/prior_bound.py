"""Where the prior says the target can be: a box the prior's error is declared to stay in.

A prior is a Gaussian belief, but what it was made from is a bound: a first detection puts
the fruit on its ray, its range off by at most e and its bearing by at most l each way
(``episode.prior = "detection"``); the paper's protocol puts it within ±e of a coarse guess
on each axis (``cube``). The Gaussian keeps only those uniforms' σ (e/√3), under which a
neighbour 6 cm along the ray is a 2σ event; the bound says it is not the target at all.

Seen in clusters of large fruit (beefsteak, r 33.5 mm), the target behind a neighbour that
hides it from the first views: the neighbour, 62-76 mm from the target, measured and
localised to a millimetre, the episode ``converged`` on the wrong fruit. A fruit localised
outside the bound (by more than its own 3.29σ, the 99.9% two-sided line, on some axis of the
box) is not the target the prior meant (:meth:`bve_mj.loop.episode.EpisodeLoop.finish`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from bve_mj.errors import EstimationError
from bve_mj.estimation.belief import Belief

__all__ = ["OUTSIDE_Z", "PriorBound"]

OUTSIDE_Z = 3.29
"""How many of the estimate's own σ beyond the bound a fruit must lie to be outside it (the
99.9% two-sided line of one axis)."""


@dataclass(frozen=True)
class PriorBound:
    """The box centre + axes @ o, |o_i| ≤ half_widths_m[i], the target is declared to lie in.

    Attributes:
        centre_m: the box's centre in the world [m], (3,) (the prior's mean).
        axes: orthonormal columns (3, 3): the box's axes in the world (the ray to the fruit
            and two directions across it; the world's axes for a cube).
        half_widths_m: the error bound along each axis [m], (3,), each ≥ 0.
    """

    centre_m: np.ndarray
    axes: np.ndarray
    half_widths_m: np.ndarray

    def __post_init__(self) -> None:
        centre = np.array(self.centre_m, dtype=float)
        axes = np.array(self.axes, dtype=float)
        half = np.array(self.half_widths_m, dtype=float)
        if centre.shape != (3,) or axes.shape != (3, 3) or half.shape != (3,):
            raise EstimationError(
                f"prior bound needs centre (3,), axes (3, 3), half widths (3,); got "
                f"{centre.shape}, {axes.shape}, {half.shape}"
            )
        if not (np.all(np.isfinite(centre)) and np.all(np.isfinite(axes)) and np.all(np.isfinite(half))):
            raise EstimationError("prior bound holds NaN or infinite values")
        if np.any(half < 0.0):
            raise EstimationError(f"prior bound half widths must be >= 0; got {half.tolist()}")
        if not np.allclose(axes.T @ axes, np.eye(3), atol=1e-9):
            raise EstimationError("prior bound axes must be orthonormal columns")
        object.__setattr__(self, "centre_m", centre)
        object.__setattr__(self, "axes", axes)
        object.__setattr__(self, "half_widths_m", half)

    @classmethod
    def cube(cls, centre_m: np.ndarray, half_width_m: float) -> PriorBound:
        """±``half_width_m`` about ``centre_m`` on each world axis."""
        return cls(np.asarray(centre_m, dtype=float), np.eye(3), np.full(3, float(half_width_m)))

    def excess_sigmas(self, belief: Belief) -> float:
        """How far outside the box the belief's centre lies, in its own σ along the box's
        axis where that is largest (≤ 0: inside)."""
        p = belief.position
        offset = self.axes.T @ (p.mean - self.centre_m)
        sigma = np.sqrt(np.maximum(np.einsum("ij,jk,ki->i", self.axes.T, p.cov, self.axes), 0.0))
        outside = np.abs(offset) - self.half_widths_m
        return float(np.max(outside / np.maximum(sigma, 1e-12)))

    def excludes(self, belief: Belief, z: float = OUTSIDE_Z) -> bool:
        """Whether the belief's centre lies outside the box by more than ``z`` of its own σ
        along some axis: a fruit the prior does not allow to be the target."""
        if not (math.isfinite(z) and z >= 0.0):
            raise ValueError(f"z: got {z!r}; allowed: a finite number >= 0")
        return self.excess_sigmas(belief) > z
