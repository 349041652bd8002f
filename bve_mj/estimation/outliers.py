"""A view's error is heavy-tailed: most views err as the noise model says, a few by several
times that, and nothing the detector reports tells which.

One view in sixteen of the every-fruit detector's errs ten times the noise model's σ
(``bve-mj calibrate --scenes 10 --views 25 --every-fruit``, seed 1: π 0.061, κ 10.0; in five
truss scenes alone 7% of its views lie beyond 5σ, the target's and its neighbours' alike),
and their features (outline seen, neighbour share, the fit's residuals and jackknife) differ
little from the others'. A Gaussian filter fuses such a view as if it were exact, and where the
belief is still wide (a track two views old) it moves the estimate to the wrong place and
shrinks the covariance there: later views that disagree are then outvoted by a covariance
that claims a fraction of a millimetre.

The measurement's likelihood here is the scale mixture (1 - π) N(0, R) + π N(0, κ²R): the
update is each component's (the same filter), weighted by its posterior probability (its
prior share times the predictive density of the innovation, linearised at the prior) and
collapsed to one Gaussian by matching moments (one step of a Gaussian-sum filter). A view
that agrees with the belief is fused nearly as before; one that disagrees moves the belief
less and widens it, so the covariance keeps the doubt and later views can settle it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from bve_mj.estimation.belief import Belief
from bve_mj.estimation.ekf import UpdateResult
from bve_mj.estimation.models import MeasurementModel
from bve_mj.estimation.view_correlation import discounted

__all__ = ["OutlierMixture", "fit_outlier_mixture", "mixture_update"]

Update = Callable[..., UpdateResult]


@dataclass(frozen=True)
class OutlierMixture:
    """A share ``share`` (π, 0-0.5) of views err ``scale`` (κ ≥ 1) times the noise model's σ.
    π = 0 is the Gaussian noise model itself."""

    share: float = 0.0
    scale: float = 1.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.share) and 0.0 <= self.share <= 0.5):
            raise ValueError(f"outlier share must be in [0, 0.5], got {self.share!r}")
        if not (math.isfinite(self.scale) and self.scale >= 1.0):
            raise ValueError(f"outlier scale must be a finite number >= 1, got {self.scale!r}")

    @property
    def gaussian(self) -> bool:
        return self.share == 0.0 or self.scale == 1.0


def mixture_update(
    update: Update, belief: Belief, z: np.ndarray, model: MeasurementModel, mixture: OutlierMixture
) -> tuple[UpdateResult, float]:
    """``update`` (the EKF's or the UKF's, ungated) of ``belief`` by ``z`` under the scale
    mixture: the collapsed posterior (the inlier component's innovation and NIS), and the
    posterior probability that the view is an inlier. A model whose noise cannot be scaled
    (:func:`~bve_mj.estimation.view_correlation.discounted`) raises TypeError."""
    inlier = update(belief, z, model, None)
    if mixture.gaussian:
        return inlier, 1.0
    k2 = mixture.scale**2
    wide = discounted(model, 1.0 / k2, 1.0 / k2)  # its noise variances × κ²
    outlier = update(belief, z, wide, None)
    H = np.atleast_2d(model.jacobian(belief.mean))
    HPH = H @ belief.cov @ H.T
    y = np.atleast_1d(np.asarray(z, dtype=float)) - np.atleast_1d(model.predict(belief.mean))
    logs = []
    for share, m in ((1.0 - mixture.share, model), (mixture.share, wide)):
        S = HPH + np.atleast_2d(m.noise_cov)
        _, logdet = np.linalg.slogdet(S)
        logs.append(math.log(share) - 0.5 * (float(y @ np.linalg.solve(S, y)) + logdet))
    w_in = 1.0 / (1.0 + math.exp(min(logs[1] - logs[0], 700.0)))
    means = (inlier.belief.mean, outlier.belief.mean)
    mean = w_in * means[0] + (1.0 - w_in) * means[1]
    cov = np.zeros_like(belief.cov)
    for w, b in ((w_in, inlier.belief), (1.0 - w_in, outlier.belief)):
        d = b.mean - mean
        cov += w * (b.cov + np.outer(d, d))
    posterior = Belief(mean, 0.5 * (cov + cov.T))
    return UpdateResult(posterior, inlier.innovation, inlier.nis, inlier.accepted), w_in


def fit_outlier_mixture(d2: np.ndarray, dof: int, iterations: int = 500) -> OutlierMixture:
    """The scale mixture fitted by EM to the squared normalised errors ``d2`` (each a sum of
    ``dof`` squares, as the noise model normalises them): π and κ² from the responsibilities.
    Fewer than 50 errors, or none beyond the Gaussian's reach, fit no tail (π = 0)."""
    d2 = np.asarray(d2, dtype=float)
    d2 = d2[np.isfinite(d2)]
    if len(d2) < 50:
        return OutlierMixture()
    share, k2 = 0.1, max(4.0, float(np.percentile(d2, 95)) / dof)
    for _ in range(iterations):
        log_in = math.log(1.0 - share) - 0.5 * d2
        log_out = math.log(share) - 0.5 * d2 / k2 - 0.5 * dof * math.log(k2)
        g = 1.0 / (1.0 + np.exp(np.clip(log_in - log_out, -700.0, 700.0)))
        share = min(max(float(g.mean()), 1e-6), 0.5)
        k2 = max(float((g * d2).sum() / (dof * max(g.sum(), 1e-12))), 1.0)
    if share < 1e-4 or k2 <= 1.0 + 1e-9:
        return OutlierMixture()
    return OutlierMixture(share, math.sqrt(k2))
