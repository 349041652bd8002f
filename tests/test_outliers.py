"""Heavy-tailed views: the scale-mixture update against importance sampling of the same
posterior, its behaviour on a view that agrees and on one that does not, the mixture's fit,
and the noise model's fields."""

import json
import math

import numpy as np
import pytest

from bve_mj.errors import ConfigError
from bve_mj.estimation import Belief, filter_update
from bve_mj.estimation.models import BearingSizeModel
from bve_mj.estimation.noise import load_noise_model
from bve_mj.estimation.outliers import OutlierMixture, fit_outlier_mixture, mixture_update
from bve_mj.geometry import camera_rotation

K = np.array([0.45, 0.02, 0.30, 0.03])  # a fruit's centre [m] and radius
CAM = np.array([0.20, 0.0, 0.32])


def _view(sigma_rad: float) -> BearingSizeModel:
    return BearingSizeModel(CAM, camera_rotation(CAM, K[:3]), np.diag([sigma_rad**2] * 3))


def _log_mixture(model, z, x, mixture):
    """log p(z | x) under the scale mixture, for a batch of states x (N, 4)."""
    r = z - np.array([model.predict(xi) for xi in x])
    Rinv, (_, logdet) = np.linalg.inv(model.noise_cov), np.linalg.slogdet(model.noise_cov)
    d2 = np.einsum("ni,ij,nj->n", r, Rinv, r)
    k2 = mixture.scale**2
    inlier = math.log(1 - mixture.share) - 0.5 * (d2 + logdet)
    outlier = math.log(mixture.share) - 0.5 * (d2 / k2 + logdet + 3 * math.log(k2))
    return np.logaddexp(inlier, outlier)


@pytest.mark.parametrize("offset_sigmas", [0.5, 3.0, 12.0])
def test_the_mixture_update_is_the_posterior_of_the_mixture_likelihood(offset_sigmas):
    """Near-linear views (a prior of a millimetre at 0.25 m, the view's σ 2 mrad): the
    collapsed posterior's mean and covariance are those of the exact posterior under the
    mixture likelihood (importance sampling from the prior, 100,000 draws), for a view that
    agrees, one 3σ off and one 12σ off; where the Gaussian update is several σ away."""
    rng = np.random.default_rng(3)
    prior = Belief(K + np.array([0.001, -0.0005, 0.0005, 0.0]), np.diag([1e-3**2] * 4))
    model = _view(2e-3)
    mixture = OutlierMixture(0.1, 8.0)
    z = model.predict(K) + np.array([1.0, -0.5, 0.3]) * offset_sigmas * 2e-3
    got, w_in = mixture_update(filter_update("ekf"), prior, z, model, mixture)
    x = rng.multivariate_normal(prior.mean, prior.cov, 100_000)
    logw = _log_mixture(model, z, x, mixture)
    w = np.exp(logw - logw.max())
    w /= w.sum()
    mean = w @ x
    cov = (x - mean).T @ ((x - mean) * w[:, None])
    sd = np.sqrt(np.diag(cov))
    assert np.all(np.abs(got.belief.mean - mean) < 0.05 * sd)
    np.testing.assert_allclose(np.sqrt(np.diag(got.belief.cov)), sd, rtol=0.05)
    gaussian = filter_update("ekf")(prior, z, model, None).belief
    if offset_sigmas > 10:
        assert w_in < 0.01 and np.max(np.abs(gaussian.mean - mean) / sd) > 3.0
    else:
        assert w_in > 0.9


def test_a_view_far_off_the_belief_moves_it_less_and_leaves_its_doubt():
    """The silent fruit's case (truss_cluster 867963663): a belief of a millimetre, a view 40σ
    (of its own noise) off, 5σ of the belief's. The Gaussian update moves 5 mm to it and
    claims a millimetre (NEES > 1000); the mixture's moves less and its NEES stays inside the
    99.9% line. A view that agrees is fused nearly as the Gaussian update fuses it."""
    prior = Belief(K.copy(), np.diag([1e-3**2] * 4))
    model = _view(0.5e-3)
    mixture = OutlierMixture(0.1, 10.0)
    update = filter_update("ekf")

    def nees(b):
        e = b.mean[:3] - K[:3]
        return float(e @ np.linalg.solve(b.cov[:3, :3], e))

    far = model.predict(K) + np.array([0.0, 0.02, 0.0])
    gauss, (robust, w_in) = (
        update(prior, far, model, None),
        mixture_update(update, prior, far, model, mixture),
    )
    assert w_in < 0.05 and nees(gauss.belief) > 1000.0 and nees(robust.belief) < 16.27
    near = model.predict(K) + np.array([0.0, 0.5e-3, 0.0])
    gauss, (robust, w_in) = (
        update(prior, near, model, None),
        mixture_update(update, prior, near, model, mixture),
    )
    assert w_in > 0.9
    np.testing.assert_allclose(robust.belief.mean, gauss.belief.mean, atol=1e-4)
    # the few per cent chance that it is an outlier: σ across the ray up to 1.4x, σmax the same
    assert np.all(np.diag(robust.belief.cov) < 1.4**2 * np.diag(gauss.belief.cov))
    top = [np.linalg.eigvalsh(b.cov[:3, :3])[-1] for b in (robust.belief, gauss.belief)]
    assert top[0] == pytest.approx(top[1], rel=0.05)


def test_no_outliers_is_the_gaussian_update_bit_for_bit():
    prior = Belief(K + 0.001, np.diag([2e-3**2] * 3 + [1e-3**2]))
    model = _view(1e-3)
    z = model.predict(K)
    update = filter_update("ekf")
    for mixture in (OutlierMixture(), OutlierMixture(0.2, 1.0), OutlierMixture(0.0, 5.0)):
        got, w_in = mixture_update(update, prior, z, model, mixture)
        ref = update(prior, z, model, None)
        assert w_in == 1.0 and np.array_equal(got.belief.mean, ref.belief.mean)
        assert np.array_equal(got.belief.cov, ref.belief.cov) and got.nis == ref.nis


def test_the_mixture_fit_recovers_the_share_and_scale_of_drawn_errors():
    rng = np.random.default_rng(7)
    n = 20_000
    scale = np.where(rng.random(n) < 0.1, 8.0, 1.0)
    d2 = np.sum((rng.normal(size=(n, 3)) * scale[:, None]) ** 2, axis=1)
    fit = fit_outlier_mixture(d2, 3)
    assert fit.share == pytest.approx(0.1, rel=0.1) and fit.scale == pytest.approx(8.0, rel=0.05)
    gaussian = fit_outlier_mixture(np.sum(rng.normal(size=(n, 3)) ** 2, axis=1), 3)
    assert gaussian.share < 0.02 or gaussian.scale < 1.3  # no tail to speak of
    assert fit_outlier_mixture(d2[:10], 3).gaussian  # too few to fit


@pytest.mark.parametrize(("share", "scale"), [(-0.1, 5.0), (0.6, 5.0), (0.1, 0.5), (float("nan"), 2.0)])
def test_bad_outlier_fields_are_refused_naming_the_file(tmp_path, share, scale):
    with pytest.raises(ValueError, match="outlier"):
        OutlierMixture(share, scale)
    data = load_noise_model().to_json()
    data.update(outlier_share=share, outlier_scale=scale)
    path = tmp_path / "noise.json"
    path.write_text(json.dumps(data))
    with pytest.raises(ConfigError, match="noise"):
        load_noise_model(str(path))


def test_a_model_file_without_outlier_fields_is_gaussian(tmp_path):
    data = load_noise_model().to_json()
    data.pop("outlier_share", None)
    data.pop("outlier_scale", None)
    path = tmp_path / "noise.json"
    path.write_text(json.dumps(data))
    assert load_noise_model(str(path)).outliers.gaussian
