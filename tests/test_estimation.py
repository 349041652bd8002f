import numpy as np
import pytest

from bve_mj.errors import EstimationError
from bve_mj.estimation import Belief, CameraModel, RangeModel, predict, update
from bve_mj.geometry import camera_rotation


def kalman_filter(x, P, z, H, R):
    """The textbook linear Kalman filter update, written independently of bve_mj."""
    S = H @ P @ H.T + R
    K = P @ H.T @ np.linalg.inv(S)
    return x + K @ (z - H @ x), P - K @ S @ K.T


def test_camera_model_ekf_equals_exact_kalman_filter(rng):
    truth = rng.uniform(-1, 1, 3)
    x, P = truth + rng.uniform(-0.15, 0.15, 3), np.diag([0.01, 0.02, 0.005])
    belief = Belief(x, P)
    Q = np.eye(3) * 1e-6
    Sc = np.diag([0.09**2, 0.002**2, 0.003**2])
    for _ in range(20):
        c = rng.uniform(-2, 2, 3)
        Rw = camera_rotation(c, belief.mean)
        model = CameraModel(c, Rw, Sc)
        z = Rw.T @ (truth - c) + rng.multivariate_normal(np.zeros(3), Sc)
        belief = update(predict(belief, Q), z, model).belief
        # exact KF in the same coordinates: z = Rᵀ x - Rᵀ c, i.e. H = Rᵀ with offset
        P = P + Q
        x, P = kalman_filter(x, P, z + Rw.T @ c, Rw.T, Sc)
        np.testing.assert_allclose(belief.mean, x, atol=1e-12)
        np.testing.assert_allclose(belief.cov, P, atol=1e-14, rtol=1e-9)


def test_range_update_matches_hand_computation():
    # prior N((1, 0, 0), diag(0.04, 0.01, 0.01)), camera at the origin, z = 1.1, σ_xx = 0.01
    belief = Belief(np.array([1.0, 0.0, 0.0]), np.diag([0.04, 0.01, 0.01]))
    result = update(belief, np.array([1.1]), RangeModel(np.zeros(3), 0.01))
    # H = (1, 0, 0); S = 0.04 + 0.01 = 0.05; K = (0.8, 0, 0); x = 1 + 0.8·0.1 = 1.08
    np.testing.assert_allclose(result.belief.mean, [1.08, 0.0, 0.0], atol=1e-12)
    # P_xx = (1 - 0.8)² 0.04 + 0.8² 0.01 = 0.0016 + 0.0064 = 0.008 (= 0.04·0.01/0.05)
    np.testing.assert_allclose(result.belief.cov, np.diag([0.008, 0.01, 0.01]), atol=1e-15)
    assert result.nis == pytest.approx(0.1**2 / 0.05)
    assert result.accepted


def test_predict_adds_process_noise_and_keeps_mean():
    b = Belief.isotropic(np.ones(3), 0.1)
    out = predict(b, np.eye(3) * 1e-4)
    np.testing.assert_array_equal(out.mean, b.mean)
    np.testing.assert_allclose(out.cov, np.eye(3) * (0.01 + 1e-4))


def test_nis_gate_rejects_outlier_and_keeps_prior():
    belief = Belief.isotropic(np.array([1.0, 0.0, 0.0]), 0.01)
    model = RangeModel(np.zeros(3), 0.01**2)
    ok = update(belief, np.array([1.01]), model, gate_probability=0.99)
    bad = update(belief, np.array([2.0]), model, gate_probability=0.99)
    assert ok.accepted and not bad.accepted
    assert bad.belief is belief
    assert bad.nis > 1000.0


@pytest.mark.parametrize("z", [np.array([np.nan]), np.array([np.inf])])
def test_non_finite_measurement_never_enters_the_belief(z):
    belief = Belief.isotropic(np.ones(3), 0.1)
    with pytest.raises(EstimationError, match="NaN or infinite"):
        update(belief, z, RangeModel(np.zeros(3), 0.01))


def test_belief_validates():
    with pytest.raises(EstimationError):
        Belief(np.zeros(3), -np.eye(3))
    with pytest.raises(EstimationError):
        Belief(np.array([np.nan, 0, 0]), np.eye(3))
    with pytest.raises(EstimationError):
        Belief(np.zeros(2), np.eye(3))


def test_chi2_quantile_is_scipy_stats_to_the_bit():
    from scipy.stats import chi2

    from bve_mj.estimation.metrics import chi2_quantile

    p = np.array([0.001, 0.025, 0.5, 0.9, 0.95, 0.97, 0.99, 0.997, 0.999, 0.975])
    for dof in (1, 2, 3, 4, 6, 7, 60, 3000):
        assert np.array_equal(chi2_quantile(p, dof), chi2.ppf(p, dof)), dof
