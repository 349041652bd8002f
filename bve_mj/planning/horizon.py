"""Receding horizon for the BVE: plan H views, execute the first.

The greedy BVE picks the view that is best on its own. Under a step limit that can be
short-sighted: the best single step from here may lead nowhere better, where a steady turn
around the fruit builds up a wide spread of viewing directions. Here the next H camera
positions c₁..c_H are chosen together to minimise the loss of the precision fused after all
of them, M = Λo + Σ_h Λn(c_h) (the estimate held fixed: the plan does not guess what the
measurements will be), subject to every task constraint at each c_h and the step limit
between consecutive ones (c₀ = the camera now); only c₁ is executed, and the next plan
starts again from the new belief.

The sequence is started from the greedy roll-out (each view the greedy BVE's answer given
the views before it), so the horizon plan is never worse on its own objective than H greedy
steps; the loss and its gradient in all 3H coordinates are analytic (:func:`dispersion`,
:func:`max_eigenvalue` of :mod:`bve_mj.planning.losses`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from bve_mj.planning.constraints import Constraint
from bve_mj.planning.information import ObservationInformation
from bve_mj.planning.losses import dispersion, max_eigenvalue

__all__ = ["ChainedStep", "HorizonObjective", "OnView", "horizon_constraints"]


@dataclass(frozen=True)
class HorizonObjective:
    """F(c₁..c_H) = loss(Λo + Σ_h Λn(c_h)) over the stacked positions (3H,), times ``scale``."""

    info: ObservationInformation
    x_hat: np.ndarray
    prior_precision: np.ndarray
    loss: str
    trace_weight: float = 0.0
    scale: float = 1.0

    def _fused(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        cs = np.asarray(z, dtype=float).reshape(-1, 3)
        n = self.prior_precision.shape[0]
        M = self.prior_precision.copy()
        dM = np.zeros((n, n, 3 * len(cs)))
        for h, c in enumerate(cs):
            L, dL = self.info.information_derivative(c, self.x_hat)
            M = M + L
            dM[:, :, 3 * h : 3 * h + 3] = dL
        return M, dM

    def value(self, z: np.ndarray) -> float:
        """The unscaled loss of the fused precision."""
        return self.value_and_gradient(z)[0] / self.scale

    def value_and_gradient(self, z: np.ndarray) -> tuple[float, np.ndarray]:
        M, dM = self._fused(z)
        if self.loss == "dispersion":
            v, g = dispersion(M, dM)
        else:
            v, g = max_eigenvalue(M, dM, self.trace_weight)
        return self.scale * v, self.scale * g


@dataclass(frozen=True)
class OnView:
    """Task constraint ``g`` applied to view ``h`` of a stacked plan of ``views`` views."""

    g: Constraint
    h: int
    views: int

    @property
    def name(self) -> str:
        return f"{self.g.name}@{self.h}"

    def value(self, z: np.ndarray) -> float:
        return self.g.value(z[3 * self.h : 3 * self.h + 3])

    def gradient(self, z: np.ndarray) -> np.ndarray:
        out = np.zeros(3 * self.views)
        out[3 * self.h : 3 * self.h + 3] = self.g.gradient(z[3 * self.h : 3 * self.h + 3])
        return out


@dataclass(frozen=True)
class ChainedStep:
    """‖c_h - c_{h-1}‖² - r² ≤ 0 between views h - 1 and h (h ≥ 1) of a stacked plan."""

    h: int
    views: int
    step_m: float
    name: str = "chained_step"

    def value(self, z: np.ndarray) -> float:
        d = z[3 * self.h : 3 * self.h + 3] - z[3 * self.h - 3 : 3 * self.h]
        return float(d @ d) - self.step_m**2

    def gradient(self, z: np.ndarray) -> np.ndarray:
        d = z[3 * self.h : 3 * self.h + 3] - z[3 * self.h - 3 : 3 * self.h]
        out = np.zeros(3 * self.views)
        out[3 * self.h : 3 * self.h + 3] = 2.0 * d
        out[3 * self.h - 3 : 3 * self.h] = -2.0 * d
        return out


def horizon_constraints(every: Sequence[Constraint], views: int, step_m: float) -> list[Constraint]:
    """The constraints of a stacked plan: ``every`` (the task constraints and the step limit
    from the camera now) on the first view, the task constraints on every later view (all
    of ``every`` but the step limit, named ``step``), and the step between consecutive views."""
    task = [g for g in every if g.name != "step"]
    out: list[Constraint] = [OnView(g, 0, views) for g in every]
    for h in range(1, views):
        out += [OnView(g, h, views) for g in task]
        out.append(ChainedStep(h, views, step_m))
    return out
