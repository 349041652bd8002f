"""BVE objectives over the next camera position c, each with its analytic gradient.

- :class:`DispersionLoss` (eq. 10): f(c) = -ln det(Λn(c) + Λo).
- :class:`MaxEigenvalueLoss` (eq. 11): f(c) = λmax((Λn(c) + Λo)⁻¹).
- :class:`ApproachTerm` (eqs. 12-13): act(i, a, b)·‖k̂ - c‖ with act = 1/(1 + e^(-a(i - b))),
  b the set point (the paper's text writes c by mistake).
- :class:`UntriedTerm` (not the paper's): weight·Σ_j exp(-(1 - e(c)·d_j)/w), a cost for
  looking again from where views measured nothing (directions d_j from the estimate).

Λo = Σo⁻¹ is the current fused precision (the EKF's P⁻¹). With the radius (and calibration
biases) in the state, the losses score the centre's block of the fused covariance.
Gradients: ∂f/∂c_j = -tr(M⁻¹ ∂Λn/∂c_j) for the dispersion; -λ² vᵀ ∂Λn/∂c_j v for the
largest eigenpair (λ, v) of M⁻¹ (defined where λmax is simple).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

import bve_mj.linalg as la
from bve_mj.planning.information import (
    FailedViewDiscount,
    ObservationInformation,
    failed_view_floats,
    failed_view_rows,
    information_lazy,
)
from bve_mj.planning.size_information import SizeInformation

__all__ = [
    "ApproachTerm",
    "DispersionLoss",
    "Gradient",
    "LossTerm",
    "MaxEigenvalueLoss",
    "Objective",
    "UntriedTerm",
    "approach_activation",
    "dispersion",
    "max_eigenvalue",
]


class LossTerm(Protocol):
    """One additive term of the BVE objective."""

    def value(self, c: np.ndarray) -> float:
        """f(c)."""
        ...

    def value_and_gradient(self, c: np.ndarray) -> tuple[float, np.ndarray]:
        """f(c) and ∇f(c) (3,)."""
        ...

    def lazy(self, c: np.ndarray) -> tuple[float, Gradient]:
        """:meth:`value_and_gradient` with ∇f(c) computed when called (the same bits)."""
        ...


Gradient = Callable[[], np.ndarray]
"""A gradient computed when called (the optimiser asks for it at about two thirds of the
points it evaluates: not at a line search's trial points)."""


def _nuisance(M: np.ndarray) -> np.ndarray | None:
    """The block of M beyond the centre (radius, calibration biases), or None (3, 3)."""
    return M[3:, 3:] if M.shape[0] > 3 else None


def _dispersion(M: np.ndarray) -> tuple[float, Callable[[np.ndarray], np.ndarray]]:
    """:func:`dispersion`'s value, and its derivative as a function of ``dM``."""
    Minv = la.inv(M)
    value = -float(la.slogdet(M)[1])
    Mb = _nuisance(M)
    if Mb is not None:
        value += float(la.slogdet(Mb)[1])

    def gradient(dM: np.ndarray) -> np.ndarray:
        grad = -np.einsum("ik,kij->j", Minv, dM)  # -tr(M⁻¹ dM_j)
        if Mb is not None:
            grad = grad + np.einsum("ik,kij->j", la.inv(Mb), dM[3:, 3:])
        return grad

    return value, gradient


def dispersion(M: np.ndarray, dM: np.ndarray) -> tuple[float, np.ndarray]:
    """ln det of the centre's block of M⁻¹ (M (n, n) a fused precision) and its derivative
    along each of the k variables ``dM`` (n, n, k) is the derivative of M in."""
    value, gradient = _dispersion(M)
    return value, gradient(dM)


def _max_eigenvalue(M: np.ndarray, trace_weight: float) -> tuple[float, Callable[[np.ndarray], np.ndarray]]:
    """:func:`max_eigenvalue`'s value, and its derivative as a function of ``dM``."""
    if M.shape[0] > 3:  # dΣ = -[M⁻¹ dM M⁻¹]_cc
        Minv = la.inv(M)
        sig, V = la.eigh(Minv[:3, :3])
        value = float(sig[-1])
        if trace_weight:
            value += trace_weight * float(np.sum(sig))

        def gradient_n(dM: np.ndarray) -> np.ndarray:
            left = Minv[:, :3] @ V[:, -1]  # M⁻¹ E v
            grad = -np.einsum("i,ikj,k->j", left, dM, left)
            if trace_weight:
                B = Minv[:, :3] @ Minv[:3, :]  # M⁻¹ Eᵀ E M⁻¹
                grad = grad - trace_weight * np.einsum("ik,kij->j", B, dM)
            return grad

        return value, gradient_n
    w, V = la.eigh(M)
    lam = 1.0 / w[0]  # largest variance = 1 / smallest precision eigenvalue

    def gradient(dM: np.ndarray) -> np.ndarray:
        v = V[:, 0]
        grad = -(lam**2) * np.einsum("i,ikj,k->j", v, dM, v)
        if trace_weight == 0.0:
            return grad
        S = (V / w) @ V.T  # Σu = M⁻¹
        tr_grad = -np.einsum("ik,kij->j", S @ S, dM)  # ∂tr(M⁻¹) = -tr(M⁻¹ dM M⁻¹)
        return grad + trace_weight * tr_grad

    if trace_weight == 0.0:
        return lam, gradient
    return lam + trace_weight * float(np.sum(1.0 / w)), gradient


def max_eigenvalue(M: np.ndarray, dM: np.ndarray, trace_weight: float) -> tuple[float, np.ndarray]:
    """λmax + τ·tr of the centre's block of M⁻¹ and its derivative along ``dM`` (n, n, k)."""
    value, gradient = _max_eigenvalue(M, trace_weight)
    return value, gradient(dM)


@dataclass(frozen=True)
class DispersionLoss:
    """ln det of the centre's fused covariance: -ln det(Λn(c) + Λo) for a centre-only state
    (eq. 10); for a larger state, ln det([M⁻¹]_cc) = -ln det M + ln det M_bb (Schur
    complement; M = Λn(c) + Λo, bb the radius and biases).

    For the radius-in-state model (:class:`~bve_mj.planning.size_information.SizeInformation`,
    failed views discounted or not) over a state of 4, the value and gradient come from
    :meth:`~bve_mj.planning.size_information.SizeInformation.dispersion_lazy` (one pass of
    floats, the same function to rounding); every other model composes Λn and its derivative."""

    info: ObservationInformation
    x_hat: np.ndarray
    prior_precision: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "_fused", _fused_dispersion(self.info, self.x_hat, self.prior_precision))

    def _lazy(self, c: np.ndarray) -> tuple[float, Gradient] | None:
        fused: Callable[[np.ndarray], tuple[float, Gradient]] | None = self._fused  # type: ignore[attr-defined]
        if fused is None:
            return None
        try:
            return fused(c)
        except ValueError:  # M not positive definite, the camera at the estimate: the general path
            return None

    def value(self, c: np.ndarray) -> float:
        fast = self._lazy(c)
        if fast is not None:
            return fast[0]
        M = self.info.information(c, self.x_hat) + self.prior_precision
        Mb = _nuisance(M)
        return -float(la.slogdet(M)[1]) + (0.0 if Mb is None else float(la.slogdet(Mb)[1]))

    def gradient(self, c: np.ndarray) -> np.ndarray:
        return self.value_and_gradient(c)[1]

    def value_and_gradient(self, c: np.ndarray) -> tuple[float, np.ndarray]:
        fast = self._lazy(c)
        if fast is not None:
            return fast[0], fast[1]()
        L, dL = self.info.information_derivative(c, self.x_hat)
        return dispersion(L + self.prior_precision, dL)

    def lazy(self, c: np.ndarray) -> tuple[float, Gradient]:
        fast = self._lazy(c)
        if fast is not None:
            return fast
        L, dL = information_lazy(self.info, c, self.x_hat)
        value, gradient = _dispersion(L + self.prior_precision)
        return value, lambda: gradient(dL())


def _fused_dispersion(
    info: ObservationInformation, x_hat: np.ndarray, prior_precision: np.ndarray
) -> Callable[[np.ndarray], tuple[float, Gradient]] | None:
    """:meth:`SizeInformation.dispersion_lazy` for ``info`` at x̂ and Λo, or None where it does
    not apply (another model, a state other than 4)."""
    discount = info if isinstance(info, FailedViewDiscount) else None
    base = info.base if isinstance(info, FailedViewDiscount) else info
    if not isinstance(base, SizeInformation) or np.shape(x_hat) != (4,):
        return None
    rows = np.asarray(prior_precision, dtype=float).tolist()

    def lazy(c: np.ndarray) -> tuple[float, Gradient]:
        odds = None if discount is None else discount.odds_lazy(c, x_hat)
        return base.dispersion_lazy(c, x_hat, rows, odds)

    return lazy


@dataclass(frozen=True)
class MaxEigenvalueLoss:
    """λmax(Σ) + τ·tr(Σ) [m²] of the centre's fused covariance Σ = [(Λn(c) + Λo)⁻¹]_cc
    (eq. 11, τ = 0 as printed).

    Where the largest variance is repeated (after one range measurement of an isotropic
    prior it is), eq. 11 is flat: no single view lowers it. The small trace term τ breaks
    that tie towards the view that lowers the other variances most.
    """

    info: ObservationInformation
    x_hat: np.ndarray
    prior_precision: np.ndarray
    trace_weight: float = 0.0

    def value(self, c: np.ndarray) -> float:
        M = self.info.information(c, self.x_hat) + self.prior_precision
        if M.shape[0] > 3:
            v = la.eigvalsh(la.inv(M)[:3, :3])
            return float(v[-1]) + self.trace_weight * float(np.sum(v))
        w = la.eigvalsh(M)
        return 1.0 / float(w[0]) + self.trace_weight * float(np.sum(1.0 / w))

    def gradient(self, c: np.ndarray) -> np.ndarray:
        return self.value_and_gradient(c)[1]

    def value_and_gradient(self, c: np.ndarray) -> tuple[float, np.ndarray]:
        L, dL = self.info.information_derivative(c, self.x_hat)
        return max_eigenvalue(L + self.prior_precision, dL, self.trace_weight)

    def lazy(self, c: np.ndarray) -> tuple[float, Gradient]:
        L, dL = information_lazy(self.info, c, self.x_hat)
        value, gradient = _max_eigenvalue(L + self.prior_precision, self.trace_weight)
        return value, lambda: gradient(dL())


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
        return self.weight * la.norm(self.k_hat - c)

    def gradient(self, c: np.ndarray) -> np.ndarray:
        return self.value_and_gradient(c)[1]

    def value_and_gradient(self, c: np.ndarray) -> tuple[float, np.ndarray]:
        d = np.asarray(c, dtype=float) - self.k_hat
        n = la.norm(d)
        grad = self.weight * d / n if n > 0.0 else np.zeros(3)
        return self.weight * n, grad

    def lazy(self, c: np.ndarray) -> tuple[float, Gradient]:
        value, grad = self.value_and_gradient(c)
        return value, lambda: grad


@dataclass(frozen=True)
class UntriedTerm:
    """weight·Σ_j g_j(c), g_j = exp(-(1 - e(c)·d_j)/w): the failed views near c, counted.

    e(c) is the unit direction from the estimate ``k_hat`` to c, d_j (k, 3) the unit
    directions of the views that measured nothing, w = 1 - cos θ₀ (``width_rad`` = θ₀), the
    kernel of :class:`~bve_mj.planning.information.FailedViewDiscount`. That discount scales
    a view's information by its odds of a detection; once failed views surround the camera,
    those odds are ~0 everywhere within one step, the information term goes flat, and the
    optimiser stays where it is, fusing nothing view after view (seen in truss scenes: the
    camera held still until the stall rule ended the episode). This term keeps a slope
    towards views not tried yet, ``weight`` per failed view at its own direction (in the
    loss's units)."""

    k_hat: np.ndarray
    failed: np.ndarray
    width_rad: float
    weight: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "_rows", failed_view_rows(self.failed))

    def value(self, c: np.ndarray) -> float:
        return self.value_and_gradient(c)[0]

    def gradient(self, c: np.ndarray) -> np.ndarray:
        return self.value_and_gradient(c)[1]

    def value_and_gradient(self, c: np.ndarray) -> tuple[float, np.ndarray]:
        value, gradient = self.lazy(c)
        return value, gradient()

    def lazy(self, c: np.ndarray) -> tuple[float, Gradient]:
        """The value, and a function that computes the gradient (SLSQP's line search asks for
        values only)."""
        rows: tuple[tuple[float, float, float], ...] = self._rows  # type: ignore[attr-defined]
        try:
            (e0, e1, e2), r, cos, g = failed_view_floats(rows, c, self.k_hat, self.width_rad)
        except ValueError:  # the camera at the estimate: every failed view counted in full
            return self.weight * len(rows), lambda: np.zeros(3)

        def gradient() -> np.ndarray:
            # Σ_j (g_j/w)·∂(e·d_j)/∂c, ∂(e·d_j)/∂c = (d_j - (e·d_j) e)/r
            w = 1.0 - math.cos(self.width_rad)
            out0 = out1 = out2 = 0.0
            for (a, b, z), cj, gj in zip(rows, cos, g, strict=True):
                f = gj / w / r
                out0 += f * (a - cj * e0)
                out1 += f * (b - cj * e1)
                out2 += f * (z - cj * e2)
            return self.weight * np.array([out0, out1, out2])

        return self.weight * math.fsum(g), gradient


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

    def lazy(self, c: np.ndarray) -> tuple[float, Gradient]:
        """:meth:`value_and_gradient` with the gradient computed when called (the same bits)."""
        parts = [term.lazy(c) for term in self.terms]
        total = 0.0
        for v, _ in parts:
            total += v

        def gradient() -> np.ndarray:
            grad = np.zeros(3)
            for _, g in parts:
                grad = grad + g()
            return self.scale * grad

        return self.scale * total, gradient
