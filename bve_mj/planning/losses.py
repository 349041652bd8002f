"""BVE objectives over the next camera position c, each with its analytic gradient.

- :class:`DispersionLoss` (eq. 10): f(c) = -ln det(Λn(c) + Λo).
- :class:`MaxEigenvalueLoss` (eq. 11): f(c) = λmax((Λn(c) + Λo)⁻¹).
- :class:`ApproachTerm` (eqs. 12-13): act(i, a, b)·‖k̂ - c‖ with act = 1/(1 + e^(-a(i - b))),
  b the set point (the paper's text writes c by mistake).

Λo = Σo⁻¹ is the current fused precision (the EKF's P⁻¹). Gradients:
∂f/∂c_j = -tr(M⁻¹ ∂Λn/∂c_j) for the dispersion; -λ² vᵀ ∂Λn/∂c_j v for the largest
eigenpair (λ, v) of M⁻¹ (defined where λmax is simple).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from bve_mj.planning.information import ObservationInformation

__all__ = [
    "ApproachTerm",
    "DispersionLoss",
    "LossTerm",
    "MaxEigenvalueLoss",
    "Objective",
    "approach_activation",
]


class LossTerm(Protocol):
    """One additive term of the BVE objective."""

    def value(self, c: np.ndarray) -> float:
        """f(c)."""
        ...

    def value_and_gradient(self, c: np.ndarray) -> tuple[float, np.ndarray]:
        """f(c) and ∇f(c) (3,)."""
        ...


@dataclass(frozen=True)
class DispersionLoss:
    """-ln det(Λn(c) + Λo): the log-volume of the fused covariance (eq. 10)."""

    info: ObservationInformation
    k_hat: np.ndarray
    prior_precision: np.ndarray

    def value(self, c: np.ndarray) -> float:
        M = self.info.information(c, self.k_hat) + self.prior_precision
        return -float(np.linalg.slogdet(M)[1])

    def gradient(self, c: np.ndarray) -> np.ndarray:
        return self.value_and_gradient(c)[1]

    def value_and_gradient(self, c: np.ndarray) -> tuple[float, np.ndarray]:
        L, dL = self.info.information_derivative(c, self.k_hat)
        M = L + self.prior_precision
        Minv = np.linalg.inv(M)
        value = -float(np.linalg.slogdet(M)[1])
        grad = -np.einsum("ik,kij->j", Minv, dL)  # -tr(M⁻¹ dΛ_j)
        return value, grad


@dataclass(frozen=True)
class MaxEigenvalueLoss:
    """λmax((Λn(c) + Λo)⁻¹) + τ·tr((Λn(c) + Λo)⁻¹) [m²] (eq. 11, τ = 0 as printed).

    Where the largest variance is repeated (after one range measurement of an isotropic
    prior it is), eq. 11 is flat: no single view lowers it. The small trace term τ breaks
    that tie towards the view that lowers the other variances most.
    """

    info: ObservationInformation
    k_hat: np.ndarray
    prior_precision: np.ndarray
    trace_weight: float = 0.0

    def value(self, c: np.ndarray) -> float:
        w = np.linalg.eigvalsh(self.info.information(c, self.k_hat) + self.prior_precision)
        return 1.0 / float(w[0]) + self.trace_weight * float(np.sum(1.0 / w))

    def gradient(self, c: np.ndarray) -> np.ndarray:
        return self.value_and_gradient(c)[1]

    def value_and_gradient(self, c: np.ndarray) -> tuple[float, np.ndarray]:
        L, dL = self.info.information_derivative(c, self.k_hat)
        w, V = np.linalg.eigh(L + self.prior_precision)
        lam, v = 1.0 / w[0], V[:, 0]  # largest variance = 1 / smallest precision eigenvalue
        grad = -(lam**2) * np.einsum("i,ikj,k->j", v, dL, v)
        if self.trace_weight == 0.0:
            return lam, grad
        S = (V / w) @ V.T  # Σu = M⁻¹
        tr_grad = -np.einsum("ik,kij->j", S @ S, dL)  # ∂tr(M⁻¹) = -tr(M⁻¹ dM M⁻¹)
        return lam + self.trace_weight * float(np.sum(1.0 / w)), grad + self.trace_weight * tr_grad


def approach_activation(iteration: int, aggressiveness: float, set_point: float) -> float:
    """act(i, a, b) = 1 / (1 + e^(-a (i - b))) (eq. 12, set point b); 0 when a = 0."""
    if aggressiveness == 0.0:
        return 0.0
    t = -aggressiveness * (iteration - set_point)
    return 0.0 if t > 700.0 else 1.0 / (1.0 + math.exp(t))


@dataclass(frozen=True)
class ApproachTerm:
    """weight·‖k̂ - c‖: pulls the camera towards the estimate (eq. 13)."""

    k_hat: np.ndarray
    weight: float

    def value(self, c: np.ndarray) -> float:
        return self.weight * float(np.linalg.norm(self.k_hat - c))

    def gradient(self, c: np.ndarray) -> np.ndarray:
        return self.value_and_gradient(c)[1]

    def value_and_gradient(self, c: np.ndarray) -> tuple[float, np.ndarray]:
        d = np.asarray(c, dtype=float) - self.k_hat
        n = float(np.linalg.norm(d))
        grad = self.weight * d / n if n > 0.0 else np.zeros(3)
        return self.weight * n, grad


@dataclass(frozen=True)
class Objective:
    """Sum of loss terms, times a constant ``scale`` that only conditions the optimiser."""

    terms: tuple[LossTerm, ...]
    scale: float = 1.0

    def value(self, c: np.ndarray) -> float:
        """The unscaled objective F(c) (paper units)."""
        return sum(term.value(c) for term in self.terms)

    def value_and_gradient(self, c: np.ndarray) -> tuple[float, np.ndarray]:
        total, grad = 0.0, np.zeros(3)
        for term in self.terms:
            v, g = term.value_and_gradient(c)
            total += v
            grad = grad + g
        return self.scale * total, self.scale * grad
