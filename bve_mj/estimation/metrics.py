"""The paper's error metrics (eqs. 34-37, per axis) and the Euclidean error per run.

Per-axis metrics average |μ_ij - μ̂_ij| (or its square) over runs i and axes j; the
Euclidean error is ‖μ_i - μ̂_i‖ per run. Consistency: NEES = (μ - μ̂)ᵀ P⁻¹ (μ - μ̂) and the
share of runs whose truth lies in the final 3σ ellipsoid (NEES ≤ 9; 97.07% for a
consistent 3-D Gaussian).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from bve_mj.errors import BveError
from bve_mj.estimation.models import MeasurementModel

__all__ = [
    "CHI2_3DOF_AT_9",
    "CONSISTENCY_LEVELS",
    "chi2_quantile",
    "consistency_curve",
    "consistency_metrics",
    "cramer_rao_bound",
    "euclidean_metrics",
    "nees_band",
    "paper_metrics",
]

CHI2_3DOF_AT_9 = 0.9707091134651118
"""P(χ²₃ ≤ 9): the share of a consistent 3-D Gaussian inside its 3σ ellipsoid."""


def chi2_quantile(probability: float | np.ndarray, dof: float) -> np.ndarray:
    """The χ²_dof quantile(s) at ``probability``: 2·P⁻¹(dof/2, p), P the regularised lower
    incomplete gamma function; what ``scipy.stats.chi2.ppf`` computes, to the bit, without
    importing scipy.stats (~0.7 s, once per process)."""
    from scipy.special import gammaincinv

    return np.asarray(2.0 * gammaincinv(dof / 2.0, probability))


def _pair(truth: np.ndarray, estimate: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    t = np.asarray(truth, dtype=float)
    e = np.asarray(estimate, dtype=float)
    if t.shape != e.shape or t.ndim != 2 or t.shape[0] == 0:
        raise BveError(
            f"metrics need truth and estimate of equal shape (N, M), N > 0; got {t.shape}, {e.shape}"
        )
    return t, e


def paper_metrics(truth: np.ndarray, estimate: np.ndarray) -> dict[str, float]:
    """MAPE [%], MAE [mm], RMSE [mm], MSE [mm²] exactly as eqs. 34-37 (per axis, over runs).

    ``truth`` and ``estimate`` are (N, M) in metres. MAPE divides by the true coordinate and
    blows up near zero: report it, do not steer by it.
    """
    t, e = _pair(truth, estimate)
    err = t - e
    with np.errstate(divide="ignore", invalid="ignore"):
        mape = float(np.mean(np.abs(err / t)) * 100.0)
    mse_m2 = float(np.mean(err**2))
    return {
        "mape_pct": mape,
        "mae_mm": float(np.mean(np.abs(err))) * 1e3,
        "rmse_mm": float(np.sqrt(mse_m2)) * 1e3,
        "mse_mm2": mse_m2 * 1e6,
    }


def euclidean_metrics(truth: np.ndarray, estimate: np.ndarray) -> dict[str, float]:
    """Mean, median and 95th percentile of ‖truth - estimate‖ per run [mm]."""
    t, e = _pair(truth, estimate)
    d = np.linalg.norm(t - e, axis=1) * 1e3
    return {
        "euclid_mean_mm": float(np.mean(d)),
        "euclid_median_mm": float(np.median(d)),
        "euclid_p95_mm": float(np.percentile(d, 95)),
    }


def consistency_metrics(truth: np.ndarray, estimate: np.ndarray, cov: np.ndarray) -> dict[str, float]:
    """Share of runs with the truth inside the 3σ ellipsoid [%] and the mean NEES."""
    t, e = _pair(truth, estimate)
    P = np.asarray(cov, dtype=float)
    if P.shape != (t.shape[0], t.shape[1], t.shape[1]):
        raise BveError(f"cov must be (N, M, M), got {P.shape}")
    d = t - e
    nees = np.einsum("ni,ni->n", d, np.linalg.solve(P, d[:, :, None])[:, :, 0])
    return {
        "inside_3sigma_pct": float(np.mean(nees <= 9.0) * 100.0),
        "nees_mean": float(np.mean(nees)),
    }


CONSISTENCY_LEVELS = (0.5, 0.6, 0.7, 0.8, 0.9, 0.95, 0.97, 0.99, 0.999)
"""The p of the consistency curve: share of episodes inside the p-ellipsoid, against p."""


def consistency_curve(
    nees: Sequence[float] | np.ndarray, dof: int = 3, tail_dofs: Sequence[float | None] | None = None
) -> list[tuple[float, float]]:
    """(p, share of ``nees`` values inside the p-region) for each p of
    :data:`CONSISTENCY_LEVELS`: the p-ellipsoid, NEES ≤ χ²_dof(p), of a Gaussian claim; of a
    Student-t claim of ν dof (``tail_dofs``, one per value, None for a Gaussian one) its
    p-region under its covariance (:class:`~bve_mj.estimation.claim_shape.ClaimShape`). An
    honest claim lies on the diagonal; below it, its regions are too small (overconfident),
    above, too large."""
    from bve_mj.estimation.claim_shape import claim_region

    values = np.asarray(nees, dtype=float)
    tails = [None] * values.size if tail_dofs is None else list(tail_dofs)
    if len(tails) != values.size:
        raise BveError(f"tail_dofs must give one dof per NEES value, got {len(tails)} for {values.size}")
    kept = [(x, nu) for x, nu in zip(values, tails, strict=True) if np.isfinite(x)]
    if not kept:
        return [(p, float("nan")) for p in CONSISTENCY_LEVELS]
    return [
        (p, float(np.mean([x <= claim_region(nu, p, dof) for x, nu in kept]))) for p in CONSISTENCY_LEVELS
    ]


def nees_band(
    episodes: int,
    dof: int = 3,
    probability: float = 0.95,
    tail_dofs: Sequence[float | None] | None = None,
    draws: int = 20_000,
) -> tuple[float, float]:
    """The two-sided ``probability`` band of the mean NEES of ``episodes`` honest episodes.

    Gaussian claims (``tail_dofs`` None, or every one None or inf): the sum of their NEES is
    χ² with episodes·dof degrees of freedom. Student-t claims (``tail_dofs``: each episode's
    ν, one per episode): the NEES of an honest one under its covariance is
    χ²_dof·(ν-2)/χ²_ν, whose mean over a few episodes spreads far wider than the χ² band says
    (20 episodes of ν = 5.3: 75% of honest means fall in the Gaussian band, 2.02-4.16; their
    own band is 1.59-5.69); the band is then the quantiles of ``draws`` seeded Monte Carlo
    means (the same band for the same input, to 1-2% of its width).

    Raises:
        BveError: ``tail_dofs`` does not give one ν (> 2, or None) per episode."""
    if episodes < 1:
        raise BveError(f"episodes must be >= 1, got {episodes}")
    q = np.array([(1 - probability) / 2, (1 + probability) / 2])
    nus = None if tail_dofs is None else [None if nu is None else float(nu) for nu in tail_dofs]
    if nus is not None and (len(nus) != episodes or any(nu is not None and not nu > 2.0 for nu in nus)):
        raise BveError(f"tail_dofs must give one dof > 2 (or None) per episode, got {tail_dofs!r}")
    if nus is None or all(nu is None or np.isinf(nu) for nu in nus):
        lo, hi = chi2_quantile(q, episodes * dof)
        return float(lo / episodes), float(hi / episodes)
    rng = np.random.default_rng(0)
    means = np.zeros(draws)
    for nu in nus:
        x = rng.chisquare(dof, draws)
        if nu is not None and np.isfinite(nu):
            x *= (nu - 2.0) / rng.chisquare(nu, draws)
        means += x
    lo, hi = np.quantile(means / episodes, q)
    return float(lo), float(hi)


def cramer_rao_bound(
    prior_cov: np.ndarray, models: Sequence[MeasurementModel], x_true: np.ndarray
) -> np.ndarray:
    """The Bayesian Cramér-Rao bound of the state from a prior of covariance ``prior_cov``
    (n, n) and the measurements of ``models`` (each fused once), linearised at the true state
    ``x_true`` (n,): (P0⁻¹ + Σ Hᵢᵀ Rᵢ⁻¹ Hᵢ)⁻¹. No unbiased estimator from those views does
    better on average; the final error over √tr of its centre block tells how close the
    episode came."""
    J = np.linalg.inv(np.asarray(prior_cov, dtype=float))
    for m in models:
        H = np.atleast_2d(m.jacobian(x_true))
        J = J + H.T @ np.linalg.solve(np.atleast_2d(m.noise_cov), H)
    return np.linalg.inv(J)
