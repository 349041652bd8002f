"""The declared sensor errors' share of a filter's covariance, and the claim that keeps it.

The claim's scales are the detector's: the share the calibration biases' prior and encoder
noise make is Gaussian and honest as declared, and the claim keeps it whole."""

from __future__ import annotations

import numpy as np
import pytest

from bve_mj.estimation import Belief, filter_update
from bve_mj.estimation.belief import CALIBRATION
from bve_mj.estimation.claim_shape import ClaimShape
from bve_mj.estimation.sensor_share import (
    calibration_information,
    nearest_psd,
    sensor_information,
    sensor_share,
)
from bve_mj.loop.claims import Claims

CAL_SIGMAS = (0.003, 0.003, 0.01)


class Linear:
    """z = H x + v, v ~ N(0, R): the exact Kalman filter's model."""

    def __init__(self, H: np.ndarray, R: np.ndarray) -> None:
        self.H, self.noise_cov = H, R

    def predict(self, x: np.ndarray) -> np.ndarray:
        return self.H @ x

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        return self.H


def _problem(seed: int = 3):
    """A 7-component prior (centre, radius, calibration biases) and five linear views, each
    with a detector part and a sensor (encoder-like) part of its noise."""
    rng = np.random.default_rng(seed)
    prior_cov = np.diag([1e-4, 1e-4, 4e-4, 4e-6, *np.square(CAL_SIGMAS)])
    views = []
    for _ in range(5):
        H = rng.normal(size=(3, 7))
        H[:, CALIBRATION] *= 0.5
        r_detector = np.diag(rng.uniform(1e-6, 4e-6, 3))
        r_sensor = np.diag([2e-6, 2e-6, 0.0])
        views.append((Linear(H, r_detector + r_sensor), r_detector, r_sensor))
    return prior_cov, views


@pytest.mark.parametrize("kind", ["ekf", "ukf"])
def test_the_sensor_share_is_the_covariance_the_sensor_errors_leave(kind):
    """On a linear model the filter's estimate is affine in the prior's error and the noises,
    so its error's covariance from each source is exact (by unit perturbations): the part the
    calibration biases' prior and the sensor noise make is G, the rest P - G."""
    prior_cov, views = _problem()
    update = filter_update(kind)
    truth = np.array([0.4, 0.1, 0.3, 0.03, 0.0, 0.0, 0.0])

    def error(e0: np.ndarray, noises: list[np.ndarray]) -> np.ndarray:
        belief = Belief(truth + e0, prior_cov)
        for (model, _, _), v in zip(views, noises, strict=True):
            belief = update(belief, model.H @ truth + v, model, None).belief
        return belief.mean - truth

    zero_e0, zero_v = np.zeros(7), [np.zeros(3) for _ in views]
    base = error(zero_e0, zero_v)
    cols_e0 = np.array([error(np.eye(7)[i], zero_v) - base for i in range(7)]).T  # ∂e/∂e0
    cols_v = [
        np.array(
            [
                error(zero_e0, [np.eye(3)[i] if j == k else np.zeros(3) for j in range(5)]) - base
                for i in range(3)
            ]
        ).T
        for k in range(5)
    ]  # ∂e/∂v_k
    bias_prior = np.zeros((7, 7))
    bias_prior[CALIBRATION, CALIBRATION] = prior_cov[CALIBRATION, CALIBRATION]
    from_sensors = cols_e0 @ bias_prior @ cols_e0.T + sum(
        B @ rs @ B.T for B, (_, _, rs) in zip(cols_v, views, strict=True)
    )
    from_all = cols_e0 @ prior_cov @ cols_e0.T + sum(
        B @ m.noise_cov @ B.T for B, (m, _, _) in zip(cols_v, views, strict=True)
    )

    belief = Belief(truth, prior_cov)
    for model, _, _ in views:
        belief = update(belief, model.H @ truth, model, None).belief
    S = sensor_information(Belief(truth, prior_cov), [(m, rs) for m, _, rs in views], belief.mean)
    G = sensor_share(belief.cov, S)
    np.testing.assert_allclose(from_all, belief.cov, rtol=1e-6, atol=1e-14)  # the filter is exact
    np.testing.assert_allclose(G, from_sensors, rtol=1e-6, atol=1e-14)
    assert np.linalg.eigvalsh(belief.cov - G).min() > -1e-15  # G ⪯ P
    assert 0.2 < np.trace(G) / np.trace(belief.cov) < 0.95  # a real share, not all nor nothing


def test_no_sensor_error_declared_is_no_share():
    prior = Belief(np.zeros(4), np.eye(4) * 1e-4)
    model = Linear(np.eye(3, 4), np.eye(3) * 1e-6)
    assert sensor_information(prior, [(model, None)], np.zeros(4)) is None
    assert sensor_share(prior.cov, None) is None
    assert calibration_information(4, CAL_SIGMAS) is None and calibration_information(7, None) is None
    info = calibration_information(7, CAL_SIGMAS)
    assert info is not None
    np.testing.assert_allclose(np.diag(info)[4:], 1.0 / np.square(CAL_SIGMAS))


def test_nearest_psd_floors_only_what_is_negative():
    a = np.diag([2.0, 1.0, -1e-12])
    np.testing.assert_allclose(nearest_psd(a), np.diag([2.0, 1.0, 0.0]), atol=1e-15)
    spd = np.array([[2.0, 0.5], [0.5, 1.0]])
    np.testing.assert_allclose(nearest_psd(spd), spd)


def test_the_claim_keeps_the_sensor_share_whole_and_scales_the_rest():
    """The bound is G·max(1, s²) plus the detector's part with every claim scale; the claim
    is that G plus the detector's part over ρ (ρ_r for the radius)."""
    rng = np.random.default_rng(5)
    A, B = rng.normal(size=(7, 7)), rng.normal(size=(7, 3))
    G = B @ B.T * 1e-6  # the sensors' share
    P = G + A @ A.T * 1e-6 + np.eye(7) * 1e-8  # and the detector's
    belief = Belief(np.zeros(7), P)
    claims = Claims(tail_scale=2.0, innovation_prior_dof=2.0, shape=ClaimShape(3.0, 1.5))
    innovations = [(6.0, 3.0)]  # s² = (2 + 6) / (2 + 3) = 1.6
    bound = claims.claim(belief, innovations, sensor_cov=G)
    kept = claims.sensor_part(G, innovations)
    assert kept is not None
    np.testing.assert_allclose(kept, 1.6 * G, rtol=1e-12)  # wider innovations widen it too
    np.testing.assert_allclose(bound.cov, 1.6 * G + 2.0 * 1.6 * (P - G), rtol=1e-9)
    agreeing = [(1.0, 3.0)]  # s² = 3 / 5: agreeing views do not shrink a bias
    np.testing.assert_allclose(claims.sensor_part(G, agreeing), G, rtol=1e-12)
    np.testing.assert_allclose(
        claims.claim(belief, agreeing, sensor_cov=G).cov, G + 2.0 * 0.6 * (P - G), rtol=1e-9
    )
    assert claims.sensor_part(None, innovations) is None
    unshared = claims.claim(belief, innovations)
    np.testing.assert_allclose(unshared.cov, 2.0 * 1.6 * P, rtol=1e-9)
    claim = claims.shape.claim(bound, kept)
    d = np.array([3.0**-0.5] * 3 + [1.5**-0.5] + [3.0**-0.5] * 3)
    np.testing.assert_allclose(claim.cov, kept + (bound.cov - kept) * np.outer(d, d), rtol=1e-9)
    np.testing.assert_allclose(claims.shape.claim(unshared).cov, unshared.cov * np.outer(d, d), rtol=1e-9)


def test_realistic_sensors_claim_what_their_errors_are():
    """`realistic_sensors` (2 px principal point, 1% focal, encoder noise 4e-4 rad), 20 seeded
    episodes: most of the filter's covariance there is the sensors' (encoder noise, the
    calibration biases), honest as declared. Before the claim kept that share whole it
    scaled it with the detector's second moment (m ≈ 0.43) and the claim's mean NEES was
    5.4-7.2 on four seeds (above even the Student-t claim's band); kept, 2.4-3.5. The mean
    must lie in the χ² band of 20 honest episodes' means (2.02-4.16)."""
    from bve_mj.campaigns.scenarios import load_suite, run_suite
    from bve_mj.estimation.metrics import nees_band

    result = run_suite(load_suite(only=["realistic_sensors"]), seeds=20, seed=8642, workers=2)
    rows = result.rows["realistic_sensors"]
    assert all(r["outcome"] != "failed" for r in rows)
    nees = np.mean([r["nees"] for r in rows])
    lo, hi = nees_band(len(rows))
    assert lo <= nees <= hi, nees
    assert sum(r["silent_failure"] for r in rows) == 0
