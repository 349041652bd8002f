"""The paper's error metrics (eqs. 34-37, per axis) and the Euclidean error per run.

Per-axis metrics average |μ_ij - μ̂_ij| (or its square) over runs i and axes j; the
Euclidean error is ‖μ_i - μ̂_i‖ per run. Consistency: NEES = (μ - μ̂)ᵀ P⁻¹ (μ - μ̂) and the
share of runs whose truth lies in the final 3σ ellipsoid (NEES ≤ 9; 97.07% for a
consistent 3-D Gaussian).
"""

from __future__ import annotations

import numpy as np

from bve_mj.errors import BveError

__all__ = ["CHI2_3DOF_AT_9", "consistency_metrics", "euclidean_metrics", "paper_metrics"]

CHI2_3DOF_AT_9 = 0.9707091134651118
"""P(χ²₃ ≤ 9): the share of a consistent 3-D Gaussian inside its 3σ ellipsoid."""


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
