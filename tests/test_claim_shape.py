"""The claim's shape: a Student-t whose covariance is the errors' second moment and whose
99.9% region is its bound's 99.9% ellipsoid (bve_mj.estimation.claim_shape)."""

import math

import numpy as np
import pytest

from bve_mj.estimation.belief import Belief
from bve_mj.estimation.claim_shape import GAUSSIAN, ClaimShape
from bve_mj.estimation.metrics import CONSISTENCY_LEVELS, chi2_quantile, consistency_curve, nees_band


def _t_samples(rng, nu, cov, n):
    """n draws of a 3-D Student-t of ν dof with covariance ``cov``: a Gaussian scale mixture."""
    scale = np.asarray(cov) * (nu - 2.0) / nu
    g = rng.multivariate_normal(np.zeros(3), scale, size=n)
    w = rng.chisquare(nu, size=n) / nu
    return g / np.sqrt(w)[:, None]


def test_a_gaussian_shape_is_the_chi2_ellipsoid_and_leaves_the_belief_alone():
    belief = Belief(np.array([0.4, 0.0, 0.2, 0.03]), np.diag([1e-6, 2e-6, 3e-6, 1e-8]))
    assert math.isinf(GAUSSIAN.dof)
    for p in (0.5, 0.971, 0.999):
        assert GAUSSIAN.region(p) == pytest.approx(float(chi2_quantile(p, 3)))
    assert GAUSSIAN.claim(belief) is belief
    assert GAUSSIAN.to_json() == {"bound_scale": 1.0, "dof": None, "radius_bound_scale": None}


@pytest.mark.parametrize("rho", [1.5, 3.38, 5.55])
def test_the_claims_region_at_the_decision_probability_is_its_bounds_ellipsoid(rho):
    """The loop decides with the bound (the Gaussian of ρ times the covariance): at 99.9% the
    claim's region must be exactly that ellipsoid, so no decision changes with the shape."""
    shape = ClaimShape(rho)
    assert 2.5 < shape.dof < 1e6
    assert shape.region(0.999) == pytest.approx(rho * float(chi2_quantile(0.999, 3)), rel=1e-6)
    bound = Belief(np.array([0.4, 0.0, 0.2]), np.diag([4e-6, 1e-6, 9e-6]))
    claim = shape.claim(bound)
    np.testing.assert_allclose(claim.cov * rho, bound.cov)
    np.testing.assert_array_equal(claim.mean, bound.mean)
    x = bound.mean + np.array([0.003, -0.001, 0.004])
    assert claim.mahalanobis_sq(x) == pytest.approx(rho * bound.mahalanobis_sq(x))


def test_the_radius_has_its_own_scale_and_keeps_its_correlation_with_the_centre():
    """ρ_r scales the radius' variance alone (D·P·D): the centre's block is the bound's over ρ,
    the radius' over ρ_r, their correlation the bound's; a 3-D belief (no radius) and the
    region the loop decides with do not change."""
    rng = np.random.default_rng(3)
    a = rng.normal(size=(7, 7))
    bound = Belief(np.r_[0.4, 0.0, 0.2, 0.03, 0.0, 0.0, 0.0], a @ a.T * 1e-6 + np.eye(7) * 1e-8)
    shape, same = ClaimShape(3.38, 1.6), ClaimShape(3.38)
    claim = shape.claim(bound)
    np.testing.assert_allclose(claim.cov[:3, :3], bound.cov[:3, :3] / 3.38)
    np.testing.assert_allclose(claim.cov[3, 3], bound.cov[3, 3] / 1.6)
    np.testing.assert_allclose(claim.cov[4:, 4:], bound.cov[4:, 4:] / 3.38)

    def corr(c):
        return c / np.sqrt(np.outer(np.diag(c), np.diag(c)))

    np.testing.assert_allclose(corr(claim.cov), corr(bound.cov), atol=1e-12)
    np.testing.assert_allclose(same.claim(bound).cov, bound.cov / 3.38)
    centre = Belief(bound.mean[:3], bound.cov[:3, :3])
    np.testing.assert_allclose(shape.claim(centre).cov, same.claim(centre).cov)
    assert shape.dof == same.dof and shape.region(0.999) == same.region(0.999)
    assert ClaimShape(3.38, 0.5).claim(bound).cov[3, 3] == pytest.approx(2.0 * bound.cov[3, 3])  # wider
    assert shape.to_json()["radius_bound_scale"] == 1.6


@pytest.mark.parametrize("bad", [0.0, -1.0, math.inf, math.nan, True, "2"])
def test_a_radius_scale_not_a_positive_number_is_refused(bad):
    with pytest.raises(ValueError, match="radius_bound_scale"):
        ClaimShape(2.0, bad)
    with pytest.raises(ValueError, match="radius_moment_scale"):
        ClaimShape.of_scales(1.5, 0.5, "moment_scale", bad if bad != 0.0 else -0.0)


def test_a_heavier_tail_has_fewer_degrees_of_freedom_and_a_narrower_bulk():
    light, heavy = ClaimShape(1.5), ClaimShape(5.0)
    assert heavy.dof < light.dof
    assert heavy.region(0.5) < light.region(0.5) < GAUSSIAN.region(0.5)


def test_a_true_student_t_lies_on_the_diagonal_of_its_shapes_consistency_curve(rng):
    """Draws of the t the shape describes: mean NEES 3 under its covariance, and the share
    inside each p-region is p (the Gaussian reading of the same draws is not: its bulk is too
    wide and its tail too narrow)."""
    shape = ClaimShape(3.38)
    cov = np.diag([1.0, 2.0, 0.5])
    e = _t_samples(rng, shape.dof, cov, 200_000)
    nees = np.einsum("ni,ni->n", e, np.linalg.solve(cov, e.T).T)
    assert np.mean(nees) == pytest.approx(3.0, rel=0.03)
    curve = consistency_curve(nees, tail_dofs=[shape.dof] * nees.size)
    for (p, share), level in zip(curve, CONSISTENCY_LEVELS, strict=True):
        assert share == pytest.approx(level, abs=0.004), p
    gaussian = dict(consistency_curve(nees))
    assert gaussian[0.5] > 0.55 and gaussian[0.999] < 0.99


def test_the_consistency_curve_needs_one_dof_per_value():
    from bve_mj.errors import BveError

    with pytest.raises(BveError, match="one dof per NEES value"):
        consistency_curve([1.0, 2.0], tail_dofs=[5.0])
    mixed = dict(consistency_curve([1.0, 30.0], tail_dofs=[None, 3.0]))
    assert mixed[0.999] == 1.0  # 30 is inside the t(3)'s 99.9% region, not the Gaussian's
    assert dict(consistency_curve([1.0, 30.0]))[0.999] == 0.5


def test_the_band_of_mean_nees_is_the_claims_shapes(rng):
    """20 honest episodes: a Gaussian claim's band is the χ² one; a Student-t claim's band
    holds 95% of the means of its own honest NEES (drawn here independently of the band's
    draws), where the χ² band holds only ~75% of them, and it is wider on both sides; one
    radius (1-D) the same; a huge ν is the χ² band again."""
    from bve_mj.errors import BveError

    n, shape = 20, ClaimShape(3.38)
    lo, hi = (float(x) / n for x in chi2_quantile(np.array([0.025, 0.975]), 3 * n))
    assert nees_band(n) == pytest.approx((lo, hi))
    assert nees_band(n, tail_dofs=[None] * n) == pytest.approx((lo, hi))
    assert nees_band(n, tail_dofs=[1e9] * n) == pytest.approx((lo, hi), rel=0.02)
    for dim in (3, 1):
        t_lo, t_hi = nees_band(n, dim, tail_dofs=[shape.dof] * n)
        g_lo, g_hi = nees_band(n, dim)
        assert t_lo < g_lo and t_hi > g_hi + 0.2 * dim
        e = _t_samples(rng, shape.dof, np.eye(3), 20_000 * n)[:, :dim]
        means = np.einsum("ni,ni->n", e, e).reshape(-1, n).mean(1)
        assert np.mean((means >= t_lo) & (means <= t_hi)) == pytest.approx(0.95, abs=0.01)
        assert np.mean((means >= g_lo) & (means <= g_hi)) < 0.85
    assert nees_band(n, tail_dofs=[shape.dof] * n) == nees_band(n, tail_dofs=[shape.dof] * n)  # seeded
    with pytest.raises(BveError, match="one dof > 2"):
        nees_band(n, tail_dofs=[5.0] * (n - 1))
    with pytest.raises(BveError, match="one dof > 2"):
        nees_band(2, tail_dofs=[5.0, 1.5])


@pytest.mark.parametrize("bad", [0.99, -1.0, math.inf, math.nan, True, "2"])
def test_a_shape_below_one_or_not_a_number_is_refused(bad):
    with pytest.raises(ValueError, match="bound_scale"):
        ClaimShape(bad)


def test_the_region_refuses_a_probability_outside_0_1():
    with pytest.raises(ValueError, match="probability"):
        ClaimShape(2.0).region(1.0)
