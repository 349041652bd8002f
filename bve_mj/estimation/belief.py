"""The Gaussian belief over the fruit centre."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bve_mj.errors import EstimationError

__all__ = ["Belief"]


@dataclass(frozen=True)
class Belief:
    """N(mean, cov) over the fruit centre in the world frame.

    Attributes:
        mean: estimated centre p_world [m], (3,).
        cov: covariance [m²], (3, 3), symmetric positive definite.
    """

    mean: np.ndarray
    cov: np.ndarray

    def __post_init__(self) -> None:
        mean = np.array(self.mean, dtype=float)
        cov = np.array(self.cov, dtype=float)
        if mean.shape != (3,) or cov.shape != (3, 3):
            raise EstimationError(f"belief needs mean (3,) and cov (3, 3), got {mean.shape}, {cov.shape}")
        if not (np.all(np.isfinite(mean)) and np.all(np.isfinite(cov))):
            raise EstimationError("belief holds NaN or infinite values")
        cov = 0.5 * (cov + cov.T)
        try:
            np.linalg.cholesky(cov)
        except np.linalg.LinAlgError:
            raise EstimationError(
                f"belief covariance is not positive definite: eig {np.linalg.eigvalsh(cov)}"
            ) from None
        mean.setflags(write=False)
        cov.setflags(write=False)
        object.__setattr__(self, "mean", mean)
        object.__setattr__(self, "cov", cov)

    @classmethod
    def isotropic(cls, mean: np.ndarray, sigma_m: float) -> Belief:
        """N(mean, sigma² I)."""
        return cls(np.asarray(mean, dtype=float), np.eye(3) * sigma_m**2)

    def precision(self) -> np.ndarray:
        """Σ⁻¹ [1/m²], (3, 3)."""
        return np.linalg.inv(self.cov)

    def mahalanobis_sq(self, p_world: np.ndarray) -> float:
        """(p - mean)ᵀ Σ⁻¹ (p - mean): the NEES when p is the truth."""
        d = np.asarray(p_world, dtype=float) - self.mean
        return float(d @ np.linalg.solve(self.cov, d))
