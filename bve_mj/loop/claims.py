"""What an episode claims beside its filter's belief: what no measurement model holds."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial

import numpy as np

from bve_mj.estimation import Belief
from bve_mj.estimation.claim_shape import GAUSSIAN, ClaimShape
from bve_mj.estimation.noise import NoiseModel, Outline
from bve_mj.estimation.partial_colour import partial_colour_cov
from bve_mj.estimation.sensor_share import nearest_psd

__all__ = ["Claims", "shape_of"]


@dataclass(frozen=True)
class Claims:
    """What an episode claims beside its filter's belief: what no measurement model holds.

    Attributes:
        centre_offset_cov: (3, 3) the covariance of an offset every measurement of this fruit
            shares (the detector's fruit-specific error, :meth:`bve_mj.estimation.noise.
            NoiseModel.centre_bias_cov`): no view reduces it, so the filter fuses the measured
            centre and the claim adds it to the centre's covariance.
        innovation_prior_dof: when set, the claimed covariance is scaled by
            s² = (ν₀ + Σ NIS) / (ν₀ + Σ m) over the measurements accepted since the last
            reset (m each's dimension): the noise of this fruit's views as its innovations
            tell it, against the model's (s² = 1 a priori, worth ν₀ degrees of freedom). A
            fruit whose views disagree more than the noise model says (a hard silhouette:
            elongated, in a cluster) claims less; one whose views agree better, more.
        refusal_scale: b ≥ 0: the claimed covariance is also scaled by exp(b · share of the
            views so far in which the detector found no fruit it could fit). A fruit the
            detector keeps refusing is a hard one (tilted and elongated, cut by neighbours),
            and the views it does fit share errors several times what the noise model (fitted
            over all fruits) says, mostly the same error in every view from a narrow cone,
            which the innovations cannot show. Calibrated: :func:`bve_mj.estimation.noise_fit.
            fit_noise_model` fits b to the calibration fruits' errors against their refusal
            shares (``NoiseModel.refusal_scale``).
        tail_scale: κ² ≥ 1, the claimed covariance's last factor: the detector's errors are
            heavy-tailed, and κ² makes the claim's 99.9% ellipsoid hold 99.9% of the errors
            of episode-like estimates from the calibration views (``NoiseModel.tail_scale``).
        shape: the claim's shape (:class:`~bve_mj.estimation.claim_shape.ClaimShape`): what
            :meth:`claim` returns is its **bound**, the Gaussian whose 99.9% ellipsoid is the
            claim's 99.9% region and the one the loop decides with; the claim itself is a
            Student-t of that mean whose covariance is the bound's over ``shape.bound_scale``
            (the errors' second moment: ``NoiseModel.moment_scale``). Gaussian by default.
            Every scale fitted here is the detector's: the share of the filter's covariance
            the declared sensor errors make (the calibration biases' prior, encoder noise) is
            kept whole, only ever scaled up by the innovations (:meth:`sensor_part`).
        offset_of: when set, the centre's offset covariance from what the detector saw of
            the fruit in the views fused (one :class:`~bve_mj.estimation.noise.Outline` each,
            None where not known: :meth:`bve_mj.estimation.noise.NoiseModel.centre_offset_cov`,
            which falls back to ``centre_offset_cov``'s bound over all fruits when an outline
            is missing); it replaces ``centre_offset_cov`` where :meth:`claim` is given the
            outlines.
    """

    centre_offset_cov: np.ndarray | None = None
    innovation_prior_dof: float | None = None
    refusal_scale: float = 0.0
    tail_scale: float = 1.0
    offset_of: Callable[[Sequence[Outline | None]], np.ndarray] | None = None
    shape: ClaimShape = GAUSSIAN

    @classmethod
    def of_detector(
        cls,
        noise: NoiseModel,
        fruit_radius_m: float,
        innovation_prior_dof: float,
        shape_index: float = 1.0,
        *,
        size_only: bool = False,
        partial_colour: bool = False,
    ) -> Claims:
        """The claims of a fruit of ``fruit_radius_m`` and ``shape_index`` measured by the
        calibrated detector ``noise``: its centre offset (from what the detector saw of it,
        when the claim is told), refusal scale and tail scale, with innovation scaling.

        ``size_only``: the episode measures the apparent size alone (range): the calibration's
        episode-like draws are of the camera measurement, so such an episode claims with the
        single views' κ² and the offset's bound over all fruits (``view_tail_scale``).
        ``partial_colour``: the detector fits fruit that may be coloured only in part (its
        ripe class is short of red): the offset of the coloured cap's edge is added
        (:func:`~bve_mj.estimation.partial_colour.partial_colour_cov`)."""
        extra = partial_colour_cov(noise, fruit_radius_m) if partial_colour else np.zeros((3, 3))
        bound = noise.centre_bias_cov(fruit_radius_m) + extra
        if size_only:
            return cls(
                bound, innovation_prior_dof, noise.refusal_scale, noise.view_tail_scale,
                shape=noise.view_claim_shape,
            )  # fmt: skip
        offset_of = partial(_offset_with, noise, fruit_radius_m, shape_index, extra)  # picklable
        tail = noise.tail_scale
        return cls(bound, innovation_prior_dof, noise.refusal_scale, tail, offset_of, noise.claim_shape)

    def scale(self, innovations: Sequence[tuple[float, float]]) -> float:
        """s² for these (NIS, degrees of freedom) pairs: each view's dimension, or the share
        of it a view correlated with those before adds (:func:`~bve_mj.estimation.
        view_correlation.shared_dof`) (1 without innovation scaling)."""
        if self.innovation_prior_dof is None:
            return 1.0
        nu = self.innovation_prior_dof
        return (nu + sum(n for n, _ in innovations)) / (nu + sum(m for _, m in innovations))

    def sensor_part(
        self, sensor_cov: np.ndarray | None, innovations: Sequence[tuple[float, float]]
    ) -> np.ndarray | None:
        """What the bound holds of G, the declared sensor errors' share of the filter's
        covariance (:func:`~bve_mj.estimation.sensor_share.sensor_share`): G · max(1, s²).
        The fitted scales (κ², m, b) are the detector's and leave it whole; innovations wider
        than the noise model says cannot tell whose error they are, so they widen it too,
        while innovations that agree better do not shrink a bias no innovation can show."""
        if sensor_cov is None:
            return None
        return np.asarray(sensor_cov, dtype=float) * max(1.0, self.scale(innovations))

    def claim(
        self,
        belief: Belief,
        innovations: Sequence[tuple[float, float]],
        refused_share: float = 0.0,
        outlines: Sequence[Outline | None] | None = None,
        sensor_cov: np.ndarray | None = None,
    ) -> Belief:
        """The bound of the belief the episode claims (see ``shape``), from the filter's, its
        accepted innovations, the share of its views in which the detector refused the fruit
        and, when given, what the detector saw of it in the views fused (``outlines``) and the
        declared sensor errors' share of its covariance (``sensor_cov``, G: :func:`~bve_mj.
        estimation.sensor_share.sensor_share`), which the bound holds as :meth:`sensor_part`."""
        cov = np.array(belief.cov)
        kept = self.sensor_part(sensor_cov, innovations)
        if sensor_cov is not None:
            cov = nearest_psd(cov - np.asarray(sensor_cov, dtype=float))
        cov *= self.scale(innovations)
        if self.offset_of is not None and outlines is not None:
            cov[:3, :3] += self.offset_of(outlines)
        elif self.centre_offset_cov is not None:
            cov[:3, :3] += np.asarray(self.centre_offset_cov, dtype=float)
        if self.refusal_scale > 0.0:
            cov *= math.exp(self.refusal_scale * min(max(refused_share, 0.0), 1.0))
        cov *= self.tail_scale
        return Belief(belief.mean, cov if kept is None else cov + kept)


def _offset_with(
    noise: NoiseModel,
    radius_m: float,
    shape_index: float,
    extra: np.ndarray,
    outlines: Sequence[Outline | None],
) -> np.ndarray:
    """The fruit's own offset from what was seen (``noise.centre_offset_cov``) plus ``extra``."""
    return noise.centre_offset_cov(radius_m, shape_index, outlines) + extra


def shape_of(claims: Claims | None) -> ClaimShape:
    """The shape of what a loop with these claims claims (Gaussian without claims)."""
    return GAUSSIAN if claims is None else claims.shape
