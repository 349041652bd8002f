"""The fruit's radius in the state: the bearing/size models, the UKF beside the EKF, and the
radius made observable by apparent size seen from several distances."""

import numpy as np
import pytest

from bve_mj.errors import EstimationError
from bve_mj.estimation import (
    BearingSizeModel,
    Belief,
    CameraModel,
    RangeModel,
    SizeModel,
    filter_update,
    predict,
    ukf,
    update,
)
from bve_mj.geometry import camera_rotation
from tests.conftest import finite_difference


def _state7(rng):
    k = rng.uniform(-0.3, 0.3, 3) + np.array([0.45, 0.0, 0.2])
    return np.concatenate([k, [0.028], rng.normal(0, 0.004, 2), [rng.normal(0, 0.01)]])


@pytest.mark.parametrize("dim", [4, 7])
def test_bearing_size_jacobian_matches_finite_differences(rng, dim):
    for _ in range(5):
        x = _state7(rng)[:dim]
        c = x[:3] + rng.uniform(0.15, 0.4) * np.array([-1.0, rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5)])
        aim = x[:3] + rng.normal(0.0, 0.02, 3)  # the camera looks near, not at, the fruit
        model = BearingSizeModel(c, camera_rotation(c, aim), np.diag([1e-6, 1e-6, 1e-6]))
        np.testing.assert_allclose(model.jacobian(x), finite_difference(model.predict, x, 1e-7), atol=1e-6)


@pytest.mark.parametrize("dim", [4, 7])
def test_size_jacobian_matches_finite_differences(rng, dim):
    for _ in range(5):
        x = _state7(rng)[:dim]
        model = SizeModel(x[:3] + rng.uniform(-0.4, 0.4, 3), 1e-6)
        np.testing.assert_allclose(model.jacobian(x), finite_difference(model.predict, x, 1e-7), atol=1e-6)


def test_bearing_size_model_measures_what_the_geometry_says():
    # a fruit of radius 30 mm, 0.3 m straight ahead and 0.03 m to the left of the axis
    c = np.zeros(3)
    R = np.eye(3)  # camera x = world x
    k = np.array([0.3, 0.03, 0.0])
    z = BearingSizeModel(c, R, np.eye(3) * 1e-6).predict(np.append(k, 0.03))
    np.testing.assert_allclose(z, [0.1, 0.0, np.arcsin(0.03 / np.linalg.norm(k))], atol=1e-12)
    # a principal-point offset shifts the bearing; a longer assumed focal shrinks everything
    zb = BearingSizeModel(c, R, np.eye(3) * 1e-6).predict(np.concatenate([k, [0.03, 0.01, -0.02, 0.1]]))
    np.testing.assert_allclose(zb[:2], (z[:2] + [0.01, -0.02]) / 1.1, atol=1e-12)
    assert np.tan(zb[2]) == pytest.approx(np.tan(z[2]) / 1.1)


def test_paper_models_ignore_the_rest_of_a_larger_state(rng):
    x = _state7(rng)
    c = rng.uniform(-1, 1, 3)
    for model in (RangeModel(c, 1e-4), CameraModel(c, camera_rotation(c, x[:3]), np.eye(3) * 1e-4)):
        np.testing.assert_allclose(model.predict(x), model.predict(x[:3]))
        J = model.jacobian(x)
        assert J.shape == (model.noise_cov.shape[0], 7) and not J[:, 3:].any()


def kalman_filter(x, P, z, H, R):
    S = H @ P @ H.T + R
    K = P @ H.T @ np.linalg.inv(S)
    return x + K @ (z - H @ x), P - K @ S @ K.T


@pytest.mark.parametrize("kind", ["ekf", "ukf"])
def test_both_filters_equal_the_exact_kalman_filter_on_a_linear_model(rng, kind):
    """A linear model over a 4-D state: both updates are the Kalman filter, exactly."""

    class Linear:
        def __init__(self, H, R, b):
            self.H, self.noise_cov, self.b = H, R, b

        def predict(self, x):
            return self.H @ x + self.b

        def jacobian(self, x):
            return self.H

    update_fn = filter_update(kind)
    x, P = rng.normal(size=4), np.diag([0.01, 0.02, 0.005, 1e-4])
    belief = Belief(x, P)
    truth = x + rng.normal(0, 0.05, 4)
    for _ in range(10):
        H, b = rng.normal(size=(2, 4)), rng.normal(size=2)
        R = np.diag(rng.uniform(1e-4, 1e-3, 2))
        model = Linear(H, R, b)
        z = H @ truth + b + rng.multivariate_normal(np.zeros(2), R)
        belief = update_fn(belief, z, model).belief
        x, P = kalman_filter(x, P, z - b, H, R)
        np.testing.assert_allclose(belief.mean, x, atol=1e-10)
        np.testing.assert_allclose(belief.cov, P, atol=1e-13, rtol=1e-8)


def test_ukf_and_ekf_agree_to_first_order_on_small_noise(rng):
    x = _state7(rng)[:4]
    belief = Belief(x, np.diag([1e-8, 1e-8, 1e-8, 1e-9]))
    c = x[:3] - np.array([0.3, 0.05, -0.02])
    model = BearingSizeModel(c, camera_rotation(c, x[:3]), np.diag([4e-6, 4e-6, 1e-6]))
    z = model.predict(x + rng.normal(0, 1e-4, 4))
    e, u = update(belief, z, model), ukf.update(belief, z, model)
    np.testing.assert_allclose(u.belief.mean, e.belief.mean, atol=1e-9)
    np.testing.assert_allclose(u.belief.cov, e.belief.cov, rtol=1e-4, atol=1e-16)
    assert u.nis == pytest.approx(e.nis, rel=1e-4)


def test_the_iterated_ukf_agrees_with_the_iterated_ekf_where_one_pass_does_not(rng):
    """A sharp bearing + size measurement from a prior 5 cm long along the ray (the loop's
    first views): the single-pass UKF regresses the apparent size over ±√3 σ of the prior and
    lands off the MAP; iterated (posterior linearisation) it agrees with the iterated EKF, the
    Gauss-Newton MAP, to a small share of the posterior σ."""
    truth = np.array([0.45, 0.02, 0.25, 0.028])
    c = np.array([0.20, 0.0, 0.30])
    ray = (truth[:3] - c) / np.linalg.norm(truth[:3] - c)
    cov = np.eye(4) * 1e-10
    cov[:3, :3] = 0.025**2 * np.outer(ray, ray) + 0.002**2 * (np.eye(3) - np.outer(ray, ray))
    cov[3, 3] = 0.0003**2  # a radius known well: the apparent size pins the range
    prior = Belief(np.append(truth[:3] + 0.04 * ray, 0.0281), cov)
    model = BearingSizeModel(c, camera_rotation(c, truth[:3]), np.diag([1e-6, 1e-6, 4e-7]))
    z = model.predict(truth)
    ekf10 = update(prior, z, model, iterations=10).belief
    one, ten = ukf.update(prior, z, model).belief, ukf.update(prior, z, model, iterations=10).belief
    sigma = np.sqrt(np.diag(ekf10.cov))
    assert np.max(np.abs(ten.mean - ekf10.mean) / sigma) < 0.1
    assert np.max(np.abs(one.mean - ekf10.mean) / sigma) > 0.5  # what the iteration is for
    np.testing.assert_allclose(np.diag(ten.cov), np.diag(ekf10.cov), rtol=0.1)


@pytest.mark.parametrize("kind", ["ekf", "ukf"])
def test_apparent_size_from_several_distances_recovers_the_radius(rng, kind):
    """Range-only (apparent size alone) with the radius in the state: a prior 20% off the
    true radius is recovered within 2% from views at different distances."""
    truth = np.array([0.45, 0.02, 0.25, 0.030])
    r_prior = 0.030 * 1.2
    belief = Belief(
        np.append(truth[:3] + np.array([0.01, -0.008, 0.006]), r_prior),
        np.diag([0.02**2, 0.02**2, 0.02**2, (0.2 * r_prior) ** 2]),
    )
    sigma = 0.3 / 466.0  # a third of a pixel of apparent radius, as an angle
    update_fn = filter_update(kind)
    for i in range(40):
        direction = rng.normal(size=3) * np.array([1.0, 0.6, 0.6]) - np.array([1.5, 0.0, 0.0])
        c = truth[:3] + (0.15 + 0.3 * (i % 5) / 4) * direction / np.linalg.norm(direction)
        model = SizeModel(c, sigma**2)
        z = model.predict(truth) + rng.normal(0, sigma)
        belief = update_fn(belief, z, model).belief
    assert abs(belief.mean[3] / truth[3] - 1.0) < 0.02
    assert np.linalg.norm(belief.mean[:3] - truth[:3]) < 0.005
    # and the covariance says so: the truth within its 3σ
    assert belief.mahalanobis_sq(truth) < 16.3


def test_a_size_model_needs_the_radius_in_the_state():
    with pytest.raises(EstimationError, match="radius in the state"):
        SizeModel(np.zeros(3), 1e-6).predict(np.ones(3))
    with pytest.raises(EstimationError, match="positive definite"):
        BearingSizeModel(np.zeros(3), np.eye(3), -np.eye(3))


def test_belief_layouts():
    b = Belief(np.array([1.0, 2.0, 3.0, 0.03]), np.diag([1e-4, 1e-4, 4e-4, 1e-6]))
    assert b.dim == 4 and b.radius_m == pytest.approx(0.03) and b.radius_sigma_m == pytest.approx(1e-3)
    assert b.position.dim == 3 and b.sigma_max_m == pytest.approx(0.02)
    assert b.mahalanobis_sq(np.array([1.0, 2.0, 3.02])) == pytest.approx(1.0)
    assert Belief.isotropic(np.zeros(3), 0.1).radius_m is None
    with pytest.raises(EstimationError):
        Belief(np.zeros(5), np.eye(5))
    p = predict(b, np.eye(3) * 1e-6)
    np.testing.assert_allclose(p.cov[3, 3], 1e-6) and np.testing.assert_allclose(p.cov[0, 0], 1.01e-4)


def test_ukf_carries_the_second_moment_of_a_quadratic_measurement():
    """h(x) = x₀²: with x₀ ~ N(m, s²) the measurement's mean is m² + s² and its variance
    4m²s² + 2s⁴. The unscented transform gets the mean exactly and, with its centre weight
    raised to 0 (n = 4), the variance as 4m²s² + 7s⁴/3 (the EKF: m² and 4m²s²)."""

    class Square:
        noise_cov = np.array([[1e-6]])

        def predict(self, x):
            return np.array([x[0] ** 2])

        def jacobian(self, x):
            return np.array([[2.0 * x[0], 0.0, 0.0, 0.0]])

    m, s = 0.5, 0.2
    belief = Belief(np.array([m, 0.0, 0.0, 0.03]), np.diag([s**2, 1.0, 1.0, 1.0]))
    z = np.array([1.0])
    result = ukf.update(belief, z, Square())
    S = 4 * m**2 * s**2 + 7 / 3 * s**4 + 1e-6
    assert result.innovation[0] == pytest.approx(1.0 - (m**2 + s**2))
    assert result.nis == pytest.approx((1.0 - m**2 - s**2) ** 2 / S)
