"""The shape of what an episode claims: a Student-t whose covariance is the errors' second
moment, and whose 99.9% region is the one the loop decides with.

The detector's errors are heavy-tailed. A Gaussian claim can be sized for their second
moment (mean NEES 3, the 3σ ellipsoid about right in the bulk) or for their tail (its 99.9%
ellipsoid holding 99.9% of them: no confident wrong answers), not both: sized for the tail,
its covariance is several times the errors' in the bulk. The claim is therefore a
multivariate Student-t of ν degrees of freedom whose **covariance** P is the errors' second
moment, calibrated (``NoiseModel.moment_scale``), and whose tail is as heavy as the
calibration's (``NoiseModel.tail_scale``): its 99.9% region is the 99.9% ellipsoid of the
**bound** ρ·P, the Gaussian the loop's stop rule and checks work with (unchanged by the
shape). ν follows from ρ: the t's 99.9% quantile of the NEES under P equals ρ·χ²₃(0.999).

For a t of ν dof, scale S and covariance P = ν/(ν-2)·S in d dimensions, (x-μ)ᵀS⁻¹(x-μ)/d is
F(d, ν), so the NEES under P at probability p is d·(ν-2)/ν·F⁻¹(p; d, ν); χ²_d(p) as ν → ∞.

The radius (the state's fourth component, where it has one) has a second moment of its own:
its errors are not the centre's (lighter-tailed, a smaller share of the bound), so its
variance in the claim is its bound's over ``radius_bound_scale`` (ρ_r = κ²/m_r, m_r its own
moment scale, fitted beside m), the covariance scaled as D·P·D with D = diag(1/√ρ, 1/√ρ,
1/√ρ, 1/√ρ_r): its correlations with the centre, and its being positive definite, kept.

The shape is the detector's: its errors are what ρ and ρ_r were fitted on. The share of the
filter's covariance the declared sensor errors make (the calibration biases' prior, encoder
noise: :mod:`bve_mj.estimation.sensor_share`) is Gaussian and as honest as their declared σ;
where a view knows it (``sensor_cov``, G as the bound holds it: :meth:`bve_mj.loop.claims.
Claims.sensor_part`) the claim is G + D·(bound − G)·D (a Gaussian plus a t: the t's regions,
used for both, are conservative).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from bve_mj.estimation.belief import RADIUS, Belief

__all__ = ["DECISION_PROBABILITY", "GAUSSIAN", "ClaimShape", "claim_region", "share_within", "t_quantile"]

DECISION_PROBABILITY = 0.999
"""The probability at which the claim's region and its bound's 99.9% ellipsoid coincide: the
scenario suite judges silent failures there."""

_MIN_DOF, _MAX_DOF = 2.5, 1e6


def _number(x: object) -> bool:
    return not isinstance(x, bool) and isinstance(x, int | float) and math.isfinite(x)


@dataclass(frozen=True)
class ClaimShape:
    """A claim's shape: its bound's covariance is ``bound_scale`` (ρ ≥ 1) times its own.

    ρ = 1 is a Gaussian claim (ν infinite): the covariance is the bound. ρ > 1: a Student-t
    whose ν makes its :data:`DECISION_PROBABILITY` region the bound's ellipsoid at that
    probability (ρ beyond what ν = 2.5 gives is held there: a heavier tail than that has
    hardly a second moment).
    """

    bound_scale: float = 1.0
    radius_bound_scale: float | None = None
    """ρ_r > 0: the bound's radius variance over the claim's (None: ``bound_scale``, as the
    centre's). It may be below 1: the bound's radius is no region the loop decides with."""

    def __post_init__(self) -> None:
        rho, rho_r = self.bound_scale, self.radius_bound_scale
        if not _number(rho) or rho < 1.0:
            raise ValueError(f"bound_scale must be a finite number >= 1, got {rho!r}")
        if rho_r is not None and (not _number(rho_r) or rho_r <= 0.0):
            raise ValueError(f"radius_bound_scale must be a finite number > 0 or none, got {rho_r!r}")

    @classmethod
    def of_scales(
        cls,
        tail_scale: float,
        moment_scale: float | None,
        name: str = "moment_scale",
        radius_moment_scale: float | None = None,
    ) -> ClaimShape:
        """The shape of a claim whose bound is ``tail_scale`` (κ²) and whose covariance is
        ``moment_scale`` (m) times one covariance: ρ = κ²/m (Gaussian where m is not known);
        its radius' variance ``radius_moment_scale`` (m_r) times that one's, ρ_r = κ²/m_r
        (None: as the centre's).

        Raises:
            ValueError: naming ``name`` (m_r's: ``radius_moment_scale`` in it), when m is not
                a finite number in (0, κ²] or m_r not one > 0."""
        if moment_scale is None:
            return cls()
        if not (_number(moment_scale) and 0.0 < moment_scale <= tail_scale * (1.0 + 1e-9)):
            raise ValueError(
                f"{name} must be a finite number in (0, {tail_scale:g}] (its tail scale), or none"
            )
        if radius_moment_scale is not None and not (
            _number(radius_moment_scale) and radius_moment_scale > 0.0
        ):
            raise ValueError(
                f"{name.replace('moment_scale', 'radius_moment_scale')} must be a finite number > 0, or none"
            )
        rho_r = None if radius_moment_scale is None else tail_scale / radius_moment_scale
        return cls(max(1.0, tail_scale / moment_scale), rho_r)

    @cached_property
    def dof(self) -> float:
        """ν: inf for a Gaussian claim."""
        if self.bound_scale <= 1.0 + 1e-12:
            return math.inf
        from scipy.optimize import brentq

        from bve_mj.estimation.metrics import chi2_quantile

        target = self.bound_scale * float(chi2_quantile(DECISION_PROBABILITY, 3))
        if t_quantile(DECISION_PROBABILITY, 3, _MIN_DOF) <= target:
            return _MIN_DOF
        return float(
            brentq(lambda nu: t_quantile(DECISION_PROBABILITY, 3, nu) - target, _MIN_DOF, _MAX_DOF, xtol=1e-6)
        )

    def region(self, probability: float, dim: int = 3) -> float:
        """The NEES (under the claim's covariance) within which the claim puts ``probability``
        of its mass: χ²_dim(p) for a Gaussian claim."""
        return claim_region(self.dof, probability, dim)

    def claim(self, bound: Belief, sensor_cov: np.ndarray | None = None) -> Belief:
        """The claim's own belief (mean, covariance) from its bound's; ``sensor_cov`` (G, the
        declared sensor errors' share of the bound, (n, n)) is kept whole."""
        if self.bound_scale == 1.0 and self.radius_bound_scale in (None, 1.0):
            return bound
        cov = np.asarray(bound.cov, dtype=float)
        g = None if sensor_cov is None else np.asarray(sensor_cov, dtype=float)
        d = np.full(cov.shape[0], 1.0 / math.sqrt(self.bound_scale))
        if cov.shape[0] > RADIUS and self.radius_bound_scale is not None:
            d[RADIUS] = 1.0 / math.sqrt(self.radius_bound_scale)
        if g is None:
            return Belief(bound.mean, cov * np.outer(d, d))
        return Belief(bound.mean, (cov - g) * np.outer(d, d) + g)

    def to_json(self) -> dict[str, float | None]:
        return {
            "bound_scale": self.bound_scale,
            "dof": None if math.isinf(self.dof) else self.dof,
            "radius_bound_scale": self.radius_bound_scale,
        }


GAUSSIAN = ClaimShape()
"""A Gaussian claim: the covariance is the bound (the synthetic world, no calibrated model)."""


def claim_region(dof: float | None, probability: float, dim: int = 3) -> float:
    """The NEES within which a claim of ``dof`` (None or inf: Gaussian) puts ``probability``."""
    if not 0.0 < probability < 1.0:
        raise ValueError(f"probability must lie in (0, 1), got {probability!r}")
    if dof is None or math.isinf(dof):
        from bve_mj.estimation.metrics import chi2_quantile

        return float(chi2_quantile(probability, dim))
    return t_quantile(probability, dim, dof)


def share_within(dof: float | None, nees: float, dim: int = 3) -> float:
    """The share of an honest claim of ``dof`` (None or inf: Gaussian) with NEES ≤ ``nees``:
    97.07% at 9 (the 3σ ellipsoid) for a Gaussian one, less for a heavier tail."""
    from scipy.special import fdtr, gammainc

    if dof is None or math.isinf(dof):
        return float(gammainc(dim / 2.0, nees / 2.0))
    return float(fdtr(dim, dof, nees * dof / (dim * (dof - 2.0))))


def t_quantile(probability: float, dim: int, nu: float) -> float:
    """The NEES under the covariance of a ``dim``-dimensional Student-t of ``nu`` dof at
    ``probability``."""
    from scipy.special import fdtri

    return float(dim * (nu - 2.0) / nu * fdtri(dim, nu, probability))
