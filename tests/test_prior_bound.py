"""The prior's declared bound: where the target can be (bve_mj.estimation.prior_bound)."""

import math

import numpy as np
import pytest
from scipy.stats import norm

from bve_mj.config import EpisodeConfig
from bve_mj.errors import EstimationError
from bve_mj.estimation import Belief
from bve_mj.estimation.prior_bound import OUTSIDE_Z, PriorBound
from bve_mj.loop.start import detection_prior, detection_prior_bounded


def _at(mean, sigma_m):
    return Belief(np.asarray(mean, dtype=float), np.eye(3) * sigma_m**2)


def test_a_centre_outside_the_box_by_more_than_its_own_sigmas_is_excluded():
    bound = PriorBound.cube(np.zeros(3), 0.05)
    assert not bound.excludes(_at([0.049, -0.05, 0.0], 1e-4))  # inside
    assert bound.excess_sigmas(_at([0.0, 0.0, 0.0], 1e-3)) == pytest.approx(-50.0)
    # 3 mm outside: excluded when the estimate claims 0.5 mm, not when it claims 1 mm
    assert bound.excludes(_at([0.0, 0.053, 0.0], 5e-4))
    assert not bound.excludes(_at([0.0, 0.053, 0.0], 1e-3))
    assert bound.excess_sigmas(_at([0.0, 0.0, -0.053], 1e-3)) == pytest.approx(3.0)
    assert abs(OUTSIDE_Z - norm.ppf(0.9995)) < 0.01  # the 99.9% two-sided line of one axis


def test_the_box_is_read_along_its_own_axes_with_the_estimates_sigma_there():
    """A box along a ray (x rotated 45° about z): 60 mm along the ray is outside ±50 mm, 60 mm
    across it outside ±10 mm; the σ used is the estimate's along each axis of the box."""
    c, s = math.cos(math.pi / 4), math.sin(math.pi / 4)
    U = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    bound = PriorBound(np.zeros(3), U, np.array([0.05, 0.01, 0.01]))
    along, across = U[:, 0], U[:, 1]
    assert bound.excludes(_at(0.06 * along, 1e-4))
    assert not bound.excludes(_at(0.04 * along, 1e-4))
    assert bound.excludes(_at(0.02 * across, 1e-4))
    wide_across = Belief(0.02 * across, 1e-8 * np.eye(3) + 0.01**2 * np.outer(across, across))
    assert not bound.excludes(wide_across)  # 10 mm outside, claiming σ 10 mm across
    with_radius = Belief(np.r_[0.06 * along, 0.03], np.diag([1e-8, 1e-8, 1e-8, 1e-6]))
    assert bound.excludes(with_radius)  # the centre's marginal is what counts


@pytest.mark.parametrize(
    ("centre", "axes", "half", "match"),
    [
        (np.zeros(2), np.eye(3), np.ones(3), "centre"),
        (np.zeros(3), np.eye(3), np.array([0.01, -0.01, 0.01]), ">= 0"),
        (np.zeros(3), 2.0 * np.eye(3), np.ones(3), "orthonormal"),
        (np.array([0.0, np.nan, 0.0]), np.eye(3), np.ones(3), "NaN"),
    ],
)
def test_a_bad_bound_is_refused(centre, axes, half, match):
    with pytest.raises(EstimationError, match=match):
        PriorBound(centre, axes, half)


def test_bad_z_is_refused():
    with pytest.raises(ValueError, match="z"):
        PriorBound.cube(np.zeros(3), 0.05).excludes(_at([0.0, 0.0, 0.0], 1e-3), z=float("nan"))


def test_a_detection_priors_target_always_lies_in_its_bound():
    """2,000 drawn detection priors: the truth inside each one's bound (excess ≤ 0 for an
    estimate at the truth claiming 0.1 mm), the bound's half widths √3 times the prior's σ
    along its axes (the uniforms' bound), the prior itself the one detection_prior gives."""
    ep = EpisodeConfig()
    rng = np.random.default_rng(7)
    truth = np.array([0.45, 0.05, 0.25])
    worst = -np.inf
    for i in range(2000):
        camera = truth + rng.normal(0.0, 0.1, 3) - np.array([0.3, 0.0, 0.0])
        prior, bound = detection_prior_bounded(camera, truth, ep, np.random.default_rng(i), 0.028)
        same = detection_prior(camera, truth, ep, np.random.default_rng(i), 0.028)
        np.testing.assert_array_equal(prior.mean, same.mean)
        np.testing.assert_array_equal(prior.cov, same.cov)
        worst = max(worst, bound.excess_sigmas(_at(truth, 1e-4)))
        sig = np.sqrt(np.diag(bound.axes.T @ prior.cov @ bound.axes))
        np.testing.assert_allclose(bound.half_widths_m, np.sqrt(3.0) * np.maximum(sig, 0.0), rtol=1e-9)
    assert worst <= 0.0
