"""Every analytic gradient of the planner against central finite differences."""

import math

import numpy as np
import pytest

from bve_mj.planning import (
    ApproachTerm,
    CameraInformation,
    DispersionLoss,
    DistanceBand,
    FailedViewDiscount,
    FieldOfViewCone,
    MaxEigenvalueLoss,
    Objective,
    OutsideFruit,
    PlantWall,
    RangeInformation,
    StepLimit,
    UntriedTerm,
    WorkspaceSphere,
)
from tests.conftest import finite_difference

SIGMA_C = np.diag([0.092**2, 0.0021**2, 0.0021**2])
SIGMA_C_ANISO = np.diag([0.09**2, 0.002**2, 0.004**2])


def random_spd(rng, scale=0.05):
    A = rng.standard_normal((3, 3))
    return scale**2 * (A @ A.T + 0.2 * np.eye(3))


def random_point_pair(rng):
    k = rng.uniform(-1, 1, 3)
    direction = rng.standard_normal(3)
    c = k + rng.uniform(0.3, 1.5) * direction / np.linalg.norm(direction)
    return c, k


INFOS = {
    "camera": CameraInformation(SIGMA_C),
    "camera_anisotropic": CameraInformation(SIGMA_C_ANISO),
    "range": RangeInformation(0.092**2),
    # views from three directions measured nothing: p(c)·Λn(c)
    "camera_failed_views": FailedViewDiscount(
        CameraInformation(SIGMA_C),
        np.array([[1.0, 0.0, 0.0], [0.0, 0.6, 0.8], [-0.6, 0.0, -0.8]]),
        math.radians(25.0),
    ),
}


@pytest.mark.parametrize("name", list(INFOS))
def test_information_derivative(name, rng):
    info = INFOS[name]
    for _ in range(50):
        c, k = random_point_pair(rng)
        L, dL = info.information_derivative(c, k)
        np.testing.assert_allclose(L, info.information(c, k), rtol=1e-12)
        fd = finite_difference(lambda x, k=k: info.information(x, k), c)
        np.testing.assert_allclose(dL, fd, rtol=1e-5, atol=1e-6 * np.abs(fd).max())


def _check_term(term, c, h=1e-6):
    value, grad = term.value_and_gradient(c)
    assert value == pytest.approx(term.value(c), rel=1e-12, abs=1e-15)
    fd = finite_difference(term.value, c, h=h)
    np.testing.assert_allclose(grad, fd, rtol=1e-4, atol=1e-7 * max(1.0, np.abs(fd).max()))


@pytest.mark.parametrize("name", list(INFOS))
def test_dispersion_gradient(name, rng):
    for _ in range(50):
        c, k = random_point_pair(rng)
        _check_term(DispersionLoss(INFOS[name], k, np.linalg.inv(random_spd(rng))), c)


@pytest.mark.parametrize("name", list(INFOS))
@pytest.mark.parametrize("trace_weight", [0.0, 0.5])
def test_max_eigenvalue_gradient(name, trace_weight, rng):
    checked = 0
    while checked < 50:
        c, k = random_point_pair(rng)
        loss = MaxEigenvalueLoss(INFOS[name], k, np.linalg.inv(random_spd(rng)), trace_weight)
        w = np.linalg.eigvalsh(INFOS[name].information(c, k) + loss.prior_precision)
        if w[1] - w[0] < 1e-3 * w[0]:
            continue  # λmax repeated: not differentiable there
        _check_term(loss, c)
        checked += 1


def test_max_eigenvalue_value_is_eq_11_when_tau_is_zero(rng):
    c, k = random_point_pair(rng)
    Lo = np.linalg.inv(random_spd(rng))
    loss = MaxEigenvalueLoss(INFOS["camera"], k, Lo)
    Sigma_n = INFOS["camera"].information(c, k)
    Su = np.linalg.inv(Sigma_n + Lo)
    assert loss.value(c) == pytest.approx(max(abs(np.linalg.eigvals(Su))))


def test_dispersion_value_is_eq_10(rng):
    c, k = random_point_pair(rng)
    Sigma_o = random_spd(rng)
    R = np.column_stack([(k - c) / np.linalg.norm(k - c), [-(k - c)[1], (k - c)[0], 0.0], [0.0, 0.0, 0.0]])
    R[:, 1] /= np.linalg.norm(R[:, 1])
    R[:, 2] = np.cross(R[:, 0], R[:, 1])
    Sigma_n = R @ SIGMA_C @ R.T  # eq. 3
    expected = -math.log(np.linalg.det(np.linalg.inv(Sigma_n) + np.linalg.inv(Sigma_o)))
    loss = DispersionLoss(INFOS["camera"], k, np.linalg.inv(Sigma_o))
    assert loss.value(c) == pytest.approx(expected, rel=1e-9)


def test_approach_gradient(rng):
    for _ in range(20):
        c, k = random_point_pair(rng)
        _check_term(ApproachTerm(k, rng.uniform(0.1, 2.0)), c)


def test_untried_gradient(rng):
    """The failed views' cost, near them (where its slope matters) and anywhere."""
    for _ in range(20):
        c, k = random_point_pair(rng)
        e = (c - k) / np.linalg.norm(c - k)
        near = e + rng.normal(0.0, 0.3, (3, 3))  # failed views within ~20 deg of c
        far = rng.standard_normal((2, 3))
        failed = np.vstack([near, far])
        failed /= np.linalg.norm(failed, axis=1, keepdims=True)
        term = UntriedTerm(k, failed, math.radians(rng.uniform(10.0, 40.0)), rng.uniform(0.5, 3.0))
        _check_term(term, c)
    # at the estimate there is no direction: every failed view counts in full, no slope
    value, gradient = term.value_and_gradient(k.copy())
    assert value == pytest.approx(term.weight * len(failed)) and not np.any(gradient)


def _constraints(rng):
    k = rng.uniform(-1, 1, 3)
    return [
        DistanceBand(k, 1.0, 0.1),
        WorkspaceSphere(np.array([0.0, 0.0, 0.159]), 0.645),
        OutsideFruit(k, 0.035),
        FieldOfViewCone(k, 0.035, math.radians(69)),
        PlantWall(k, 0.1),
        StepLimit(rng.uniform(-2, 2, 3), 0.2),
    ]


def test_every_constraint_gradient(rng):
    for _ in range(50):
        c = rng.uniform(-2, 2, 3)
        for g in _constraints(rng):
            fd = finite_difference(g.value, c)
            np.testing.assert_allclose(g.gradient(c), fd, rtol=1e-6, atol=1e-8, err_msg=g.name)


def test_constraint_values_match_the_paper():
    k = np.array([0.5, 0.5, 0.2])
    # eq. 20: inside the band ⟺ value ≤ 0
    band = DistanceBand(k, 1.0, 0.1)
    assert band.value(k + np.array([0.95, 0, 0])) < 0 < band.value(k + np.array([1.15, 0, 0]))
    assert band.value(k + np.array([0.85, 0, 0])) > 0
    # eqs. 17-19: the wall is d = 0.1 m in front of the fruit, towards the robot base
    wall = PlantWall(k, 0.1)
    e_n = np.array([1.0, 1.0, 0.0]) / np.sqrt(2)
    assert wall.value(k - 0.05 * e_n) > 0 > wall.value(k - 0.15 * e_n)
    # eq. 16 corrected: fruit of radius r in a cone of half-angle θ ⟺ d ≥ r / sin θ
    cone = FieldOfViewCone(k, 0.035, math.radians(69))
    d_min = 0.035 / math.sin(math.radians(34.5))
    assert cone.value(k + np.array([d_min * 1.01, 0, 0])) < 0 < cone.value(k + np.array([d_min * 0.99, 0, 0]))


# ---------------------------------------------------------------- the radius in the state
from bve_mj.estimation import BearingSizeModel, SizeModel  # noqa: E402
from bve_mj.geometry import camera_rotation  # noqa: E402
from bve_mj.planning.size_information import SizeInformation  # noqa: E402

SIZE_INFOS = {
    "bearing_size": SizeInformation((2e-7, 1e-9), (1e-7, 2e-9), bearing=True),
    "size_only": SizeInformation((2e-7, 1e-9), (1e-7, 2e-9), bearing=False),
    # the close view's term c·T⁴ (NoiseModel's "near"), a few % of the floor at T = 0.1
    "bearing_size_near": SizeInformation((2e-7, 1e-9, 1e-4), (1e-7, 2e-9, 5e-5), bearing=True),
}


def random_state_pair(rng, dim):
    k = rng.uniform(-0.5, 0.5, 3)
    direction = rng.standard_normal(3)
    c = k + rng.uniform(0.12, 0.6) * direction / np.linalg.norm(direction)
    x = np.concatenate([k, [rng.uniform(0.01, 0.04)], rng.normal(0, 0.004, 2), [rng.normal(0, 0.02)]])
    return c, x[:dim]


def random_spd_n(rng, n):
    A = rng.standard_normal((n, n))
    S = 0.03**2 * (A @ A.T + 0.2 * np.eye(n))
    return S


@pytest.mark.parametrize("name", list(SIZE_INFOS))
@pytest.mark.parametrize("dim", [4, 7])
def test_size_information_derivative(name, dim, rng):
    info = SIZE_INFOS[name]
    for _ in range(30):
        c, x = random_state_pair(rng, dim)
        L, dL = info.information_derivative(c, x)
        np.testing.assert_allclose(L, info.information(c, x), rtol=1e-12)
        fd = finite_difference(lambda cc, x=x: info.information(cc, x), c, h=1e-7)
        np.testing.assert_allclose(dL, fd, rtol=1e-5, atol=1e-6 * np.abs(fd).max())


@pytest.mark.parametrize("dim", [4, 7])
def test_size_information_is_the_filters_model(dim, rng):
    """What the planner expects of a view is Hᵀ R⁻¹ H of the very model the filter fuses,
    for a camera looking at the estimate, with the noise at that apparent size."""
    bearing_var, size_var = (2e-7, 1e-9), (1e-7, 2e-9)
    for _ in range(10):
        c, x = random_state_pair(rng, dim)
        rho = np.linalg.norm(x[:3] - c)
        T = np.tan(np.arcsin(x[3] / rho))
        R = camera_rotation(c, x[:3])
        noise = np.diag([bearing_var[0] + bearing_var[1] * T**2] * 2 + [size_var[0] + size_var[1] * T**2])
        for bearing in (True, False):
            if bearing:
                H, W = BearingSizeModel(c, R, noise).jacobian(x), np.linalg.inv(noise)
            else:
                H, W = SizeModel(c, noise[2, 2]).jacobian(x), np.array([[1.0 / noise[2, 2]]])
            expected = H.T @ W @ H
            got = SizeInformation(bearing_var, size_var, bearing).information(c, x)
            np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-9 * np.abs(expected).max())


@pytest.mark.parametrize("name", list(SIZE_INFOS))
@pytest.mark.parametrize("dim", [4, 7])
def test_centre_block_losses_gradients(name, dim, rng):
    for _ in range(20):
        c, x = random_state_pair(rng, dim)
        Lo = np.linalg.inv(random_spd_n(rng, dim))
        # steps of 1e-5: M's condition reaches 1e6 in these draws, the value's rounding
        # ~1e-12, which differences over 1e-6 would turn into 1e-6 of noise
        _check_term(DispersionLoss(SIZE_INFOS[name], x, Lo), c, h=1e-5)
        for tau in (0.0, 0.5):
            loss = MaxEigenvalueLoss(SIZE_INFOS[name], x, Lo, tau)
            M = SIZE_INFOS[name].information(c, x) + Lo
            s = np.linalg.eigvalsh(np.linalg.inv(M)[:3, :3])
            if s[-1] - s[-2] > 1e-3 * s[-1]:
                _check_term(loss, c)


def test_centre_block_losses_score_the_centre_covariance(rng):
    c, x = random_state_pair(rng, 7)
    Lo = np.linalg.inv(random_spd_n(rng, 7))
    info = SIZE_INFOS["bearing_size"]
    Sigma = np.linalg.inv(info.information(c, x) + Lo)[:3, :3]
    assert DispersionLoss(info, x, Lo).value(c) == pytest.approx(math.log(np.linalg.det(Sigma)), rel=1e-9)
    assert MaxEigenvalueLoss(info, x, Lo, 0.5).value(c) == pytest.approx(
        np.linalg.eigvalsh(Sigma)[-1] + 0.5 * np.trace(Sigma), rel=1e-9
    )


def _same(a, b):
    a, b = np.asarray(a), np.asarray(b)
    return np.array_equal(a, b) and np.array_equal(np.signbit(a), np.signbit(b))


@pytest.mark.parametrize("dim", [3, 4, 7])
def test_lazy_objective_is_the_eager_one_bit_for_bit(dim, rng):
    """The optimiser takes the objective's gradient only where it needs it (Objective.lazy):
    value and gradient must be the very bits of value_and_gradient, whatever the model."""
    infos = {**INFOS, **SIZE_INFOS} if dim > 3 else INFOS
    for name, info in infos.items():
        for _ in range(10):
            c, x = random_state_pair(rng, dim)
            if name in SIZE_INFOS and dim == 3:
                continue
            Lo = np.linalg.inv(random_spd_n(rng, dim))
            terms = [DispersionLoss(info, x, Lo)] + [MaxEigenvalueLoss(info, x, Lo, t) for t in (0.0, 0.5)]
            for term in terms:
                untried = UntriedTerm(x[:3], np.array([[1.0, 0.0, 0.0], [0.0, 0.6, 0.8]]), 0.4, 1.0)
                for objective in (
                    Objective((term,), 1e6),
                    Objective((term, ApproachTerm(x[:3], 0.3))),
                    Objective((term, untried)),
                ):
                    value, gradient = objective.lazy(c)
                    ref_value, ref_gradient = objective.value_and_gradient(c)
                    assert _same(value, ref_value) and _same(gradient(), ref_gradient), name


@pytest.mark.parametrize("bearing", [True, False])
@pytest.mark.parametrize("failed", [False, True])
@pytest.mark.parametrize("taken", [False, True])
def test_the_fused_dispersion_is_the_composed_one(bearing, failed, taken, rng):
    """:meth:`SizeInformation.dispersion_lazy` (one pass of floats, what the planner runs)
    against the loss composed from :meth:`information_lazy` (and the failed views' discount,
    and the views already taken), value and gradient, in every branch; and at the skin, where
    the apparent size is clipped, against finite differences of its own value."""
    from bve_mj.estimation.view_correlation import ViewCorrelation
    from bve_mj.planning.information import information_lazy
    from bve_mj.planning.losses import _dispersion

    corr = (ViewCorrelation(0.5, 0.03, 0.7, 0.02), ViewCorrelation(0.3, 0.05, 0.8, 0.03))
    for i in range(40):
        c, x = random_state_pair(rng, 4)
        e = (c - x[:3]) / np.linalg.norm(c - x[:3])
        near = [e + rng.normal(0.0, 0.2, 3) for _ in range(3)]
        directions = np.array([d / np.linalg.norm(d) for d in near])
        at = c + rng.normal(0.0, 0.015, (3, 3))  # cameras close by: the nearby part counts
        info = SizeInformation(
            (2e-7, 1e-9), (1e-7, 2e-9), bearing, directions if taken else None, corr, at if taken else None
        )
        if failed:
            info = FailedViewDiscount(info, directions[:2], math.radians(25.0))
        Lo = np.linalg.inv(random_spd_n(rng, 4))
        loss = DispersionLoss(info, x, Lo)
        assert loss._fused is not None  # the fast path is the one taken
        value, gradient = loss.lazy(c)
        L, dL = information_lazy(info, c, x)
        expected, d_expected = _dispersion(L + Lo)
        assert value == pytest.approx(expected, rel=1e-11)
        np.testing.assert_allclose(
            gradient(), d_expected(dL()), rtol=1e-6, atol=1e-9 * np.abs(d_expected(dL())).max()
        )
        if i < 5:  # the camera at the fruit's skin: r/ρ > 0.99, the apparent size held
            skin = x[:3] + 0.995 * x[3] * e
            L, dL = information_lazy(info, skin, x)
            fd = finite_difference(lambda cc, info=info, x=x: information_lazy(info, cc, x)[0], skin, h=1e-8)
            np.testing.assert_allclose(dL(), fd, rtol=1e-4, atol=1e-5 * np.abs(fd).max())
            value, gradient = loss.lazy(skin)
            expected, d_expected = _dispersion(L + Lo)  # M's condition 1e8-1e10 at 1 cm
            assert value == pytest.approx(expected, rel=1e-7)
            np.testing.assert_allclose(
                gradient(), d_expected(dL()), rtol=1e-4, atol=1e-5 * np.abs(d_expected(dL())).max()
            )
    # a state with biases takes the composed path
    x7 = np.concatenate([x, [0.0, 0.0, 0.0]])
    assert DispersionLoss(SIZE_INFOS["bearing_size"], x7, np.linalg.inv(random_spd_n(rng, 7)))._fused is None
