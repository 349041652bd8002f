"""Views from nearby directions share their errors: the share a new view adds, its gradient,
its fit from calibration pairs, and the filter and the planner counting views by it."""

import json
import math

import numpy as np
import pytest

from bve_mj.config import CameraConfig, FilterConfig
from bve_mj.estimation import BearingSizeModel, Belief
from bve_mj.estimation.noise_fit import fit_noise_model
from bve_mj.estimation.view_correlation import (
    ViewCorrelation,
    ViewShares,
    discounted,
    fit_view_correlation,
    new_view_share,
)
from bve_mj.geometry import camera_rotation
from bve_mj.loop.episode import run_episode
from bve_mj.planning.plan import ViewPlan
from bve_mj.planning.size_information import SizeInformation
from bve_mj.sim.world import Observation
from tests.conftest import finite_difference

CORR = ViewCorrelation(weight=0.5, width=0.03)


def _unit(v):
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


def _n_eff(corr, dirs):
    """1ᵀ C⁻¹ 1 by brute force."""
    C = corr.rho(dirs @ dirs.T)
    np.fill_diagonal(C, 1.0)
    return float(np.ones(len(dirs)) @ np.linalg.solve(C, np.ones(len(dirs))))


def test_a_view_is_worth_what_it_adds_to_the_effective_number_of_views(rng):
    e = _unit([1.0, 0.2, -0.1])
    assert new_view_share(ViewCorrelation(), np.array([e]), e)[0] == 1.0  # independent views
    assert new_view_share(CORR, np.empty((0, 3)), e)[0] == 1.0  # the first view
    w = CORR.weight
    # the same direction again: n_eff goes from 1 to 2 / (1 + w)
    assert new_view_share(CORR, np.array([e]), e)[0] == pytest.approx((1 - w) / (1 + w))
    assert new_view_share(CORR, np.array([e]), -e)[0] == pytest.approx(1.0, abs=1e-6)  # opposite
    for _ in range(20):
        taken = np.array([_unit(rng.normal(size=3) + [2, 0, 0]) for _ in range(rng.integers(1, 6))])
        new = _unit(rng.normal(size=3) + [2, 0, 0])
        share = new_view_share(CORR, taken, new)[0]
        expected = _n_eff(CORR, np.vstack([taken, new])) - _n_eff(CORR, taken)
        assert share == pytest.approx(expected, rel=1e-9)
        assert 0.0 < share <= 1.0


def test_the_share_gradient_matches_finite_differences(rng):
    for _ in range(20):
        taken = np.array([_unit(rng.normal(size=3) + [2, 0, 0]) for _ in range(3)])
        e = _unit(rng.normal(size=3) + [2, 0, 0])
        _, grad = new_view_share(CORR, taken, e)
        fd = finite_difference(lambda v, t=taken: new_view_share(CORR, t, v)[0], e, h=1e-7)
        np.testing.assert_allclose(grad, fd, rtol=1e-5, atol=1e-8)


def test_the_fit_recovers_a_known_correlation(rng):
    """Pairs of views whose errors correlate by 0.45 · exp(-(1 - cos θ)/0.05)."""
    truth = ViewCorrelation(weight=0.45, width=0.05)
    cos, prod = [], []
    for _ in range(300):
        dirs = np.array([_unit(rng.normal(size=3) * 0.5 + [1, 0, 0]) for _ in range(10)])
        C = truth.rho(dirs @ dirs.T)
        np.fill_diagonal(C, 1.0)
        z = np.linalg.cholesky(C) @ rng.standard_normal(10)
        for i in range(10):
            for j in range(i + 1, 10):
                cos.append(dirs[i] @ dirs[j])
                prod.append(z[i] * z[j])
    fitted = fit_view_correlation(cos, prod)
    assert fitted.weight == pytest.approx(0.45, abs=0.08)
    assert fitted.half_angle_deg() == pytest.approx(truth.half_angle_deg(), rel=0.3)
    assert fit_view_correlation(cos, rng.permutation(prod)).weight < 0.1  # shuffled: none


def test_calibration_fits_the_view_correlation_of_its_rows(rng):
    """Calibration rows whose per-view errors share a correlated part across directions."""
    f = CameraConfig().focal_px
    truth_corr = ViewCorrelation(weight=0.5, width=0.04)
    rows = []
    for k in range(60):
        truth = np.array([0.45, 0.0, 0.2]) + rng.normal(0, 0.05, 3)
        away = [_unit(rng.normal(size=3) * 0.5 - [1, 0, 0]) for _ in range(12)]
        cams = [truth + rng.uniform(0.15, 0.4) * d for d in away]
        dirs = np.array([_unit(c - truth) for c in cams])
        C = truth_corr.rho(dirs @ dirs.T)
        np.fill_diagonal(C, 1.0)
        L = np.linalg.cholesky(C)
        zu, zv, za = (L @ rng.standard_normal(12) for _ in range(3))
        for v, c in enumerate(cams):
            rho = float(np.linalg.norm(truth - c))
            r_px = f * math.tan(math.asin(0.03 / rho))
            rows.append({
                "scenario": "synthetic", "scene_seed": k, "view": v, "detected": True,
                "radius_px": r_px, "arc_deg": 360.0, "centre_fit_px": 0.3, "radius_fit_px": 0.3,
                "fruit_shape_index": 1.0, "distance_m": rho, "true_radius_m": 0.03,
                "camera_rotation": camera_rotation(c, truth).tolist(),
                "camera_position_m": c.tolist(), "truth_m": truth.tolist(),
                "err_u_px": 0.2 * zu[v], "err_v_px": 0.2 * zv[v], "err_alpha_px": 0.2 * za[v],
            })  # fmt: skip
    model, _ = fit_noise_model(rows, CameraConfig(), "test")
    assert model.radius_correlation.weight == pytest.approx(0.5, abs=0.12)
    # the lateral centre components rotate with the view, so their correlation reads lower
    assert 0.2 < model.centre_correlation.weight < 0.65
    reloaded = type(model)(**{**model.__dict__})
    assert reloaded.radius_correlation == model.radius_correlation


def test_discounted_divides_each_components_variance_by_its_share():
    c, k = np.array([0.2, 0.0, 0.3]), np.array([0.45, 0.0, 0.2])
    R = np.diag([1e-6, 2e-6, 3e-6])
    m = discounted(BearingSizeModel(c, camera_rotation(c, k), R), 0.5, 0.25)
    np.testing.assert_allclose(np.diag(m.noise_cov), [2e-6, 4e-6, 1.2e-5])


class _SamePlace:
    """A world that measures the same thing from the same pose every view."""

    def __init__(self, z, model):
        self.z, self.model = z, model

    @property
    def p_world_camera(self):
        return self.model.p_world_camera

    def move_camera(self, plan):
        pass

    def observe(self, belief=None):
        return Observation(self.z, self.model)


class _Hold:
    def __init__(self):
        self.fused = []

    def plan(self, belief, p_world_camera, iteration):
        return ViewPlan(p_world_camera, belief.centre_m, "optimal", True, 0.0)

    def note_fused_view(self, p_world_camera, p_world_target, *, restart=False):
        self.fused.append(p_world_camera.copy())


def test_the_loop_fuses_repeated_views_as_the_share_they_add():
    """Five views from one place, errors correlated by w = 0.5 at 0°: the filter's information
    from them is n_eff = 5 / (1 + 4w) = 5/3 single views (1/σ² of the predicted measurement),
    not 5; independent views give 5."""
    k, c = np.array([0.45, 0.0, 0.2, 0.03]), np.array([0.2, 0.0, 0.3])
    model = BearingSizeModel(c, camera_rotation(c, k[:3]), np.diag([1e-6, 1e-6, 1e-6]))
    z = model.predict(k)
    prior = Belief(k, np.diag([0.05**2] * 3 + [0.01**2]))
    H = model.jacobian(k)
    prior_info = np.linalg.inv(H @ prior.cov @ H.T)
    cfg = FilterConfig(gate_probability=None, process_sigma_m=0.0)
    for corr, n_eff in ((None, 5.0), ((CORR, CORR), 5.0 / (1.0 + 4 * CORR.weight))):
        planner = _Hold()
        result = run_episode(_SamePlace(z, model), planner, prior, cfg, 4, correlation=corr)
        # (H P Hᵀ)⁻¹ = (H P0 Hᵀ)⁻¹ + Σ R_i⁻¹ for a linear(ised) model: the precision of the
        # predicted measurement grows by n_eff single views
        info = np.linalg.inv(H @ result.final.cov @ H.T)
        np.testing.assert_allclose(info - prior_info, n_eff * 1e6 * np.eye(3), rtol=1e-3, atol=1e-3 * 1e6)
        assert len(planner.fused) == (5 if corr is not None else 0)


def test_view_shares_are_new_view_shares_and_each_set_of_views_is_made_once(rng, monkeypatch):
    """The every-fruit planner's :class:`ViewShares` gives :func:`new_view_share`'s values bit
    for bit, for each fruit's own directions taken, and makes each set's views once."""
    from bve_mj.estimation import view_correlation as vc

    corr = (ViewCorrelation(0.3, 0.03), ViewCorrelation(0.5, 0.08))
    made = []
    of = vc.TakenViews.of.__func__

    def counting(cls, c, directions):
        made.append(len(directions))
        return of(cls, c, directions)

    monkeypatch.setattr(vc.TakenViews, "of", classmethod(counting))
    shares = ViewShares(*corr)
    fruits = [np.array([_unit(rng.normal(size=3)) for _ in range(k)]) for k in (1, 2, 4)]
    for _ in range(3):
        for taken in fruits:
            e = _unit(rng.normal(size=3))
            assert shares(taken, e) == tuple(of(vc.TakenViews, x, taken).share(e)[0] for x in corr)
    assert len(made) == 2 * len(fruits)  # the centre's and the radius' views, once per fruit
    shares(fruits[2][:3], e)  # another set of directions: made anew
    assert len(made) == 2 * len(fruits) + 2


@pytest.mark.parametrize("bearing", [True, False])
def test_the_planner_expects_of_a_view_the_share_the_filter_will_fuse(rng, bearing):
    base = SizeInformation((2e-7, 1e-9), (1e-7, 2e-9), bearing=bearing)
    corr = (ViewCorrelation(0.3, 0.03), ViewCorrelation(0.5, 0.08))
    k = np.array([0.45, 0.0, 0.2, 0.03])
    taken = np.array([_unit([-1, 0.1, 0.2]), _unit([-1, -0.3, 0.1])])
    info = SizeInformation(base.bearing_var, base.size_var, bearing, taken=taken, correlation=corr)
    for _ in range(10):
        c = k[:3] + rng.uniform(0.15, 0.35) * _unit(rng.normal(size=3) * 0.4 + [-1, 0, 0])
        e = _unit(c - k[:3])
        fc, fr = (new_view_share(x, taken, e)[0] for x in corr)
        rho = np.linalg.norm(k[:3] - c)
        T = math.tan(math.asin(k[3] / rho))
        R = np.diag([2e-7 + 1e-9 * T**2] * 2 + [1e-7 + 2e-9 * T**2])
        model = BearingSizeModel(c, camera_rotation(c, k[:3]), R)
        H, W = model.jacobian(k), np.linalg.inv(discounted(model, fc, fr).noise_cov)
        if not bearing:
            H, W = H[2:], W[2:, 2:]
        np.testing.assert_allclose(info.information(c, k), H.T @ W @ H, rtol=1e-9, atol=1e-3)
        _, dL = info.information_derivative(c, k)
        fd = finite_difference(lambda cc: info.information(cc, k), c, h=1e-7)
        np.testing.assert_allclose(dL, fd, rtol=1e-5, atol=1e-6 * np.abs(fd).max())


def test_the_shipped_model_holds_the_correlation_and_a_bad_one_is_refused(tmp_path):
    from bve_mj.errors import ConfigError
    from bve_mj.estimation.noise import load_noise_model

    model = load_noise_model("default")
    for corr in (model.centre_correlation, model.radius_correlation):
        assert 0.05 < corr.weight < 0.9 and 3.0 < corr.half_angle_deg() < 45.0
    doc = model.to_json()
    del doc["radius_correlation"]  # a file from before: views independent
    (tmp_path / "old.json").write_text(json.dumps(doc))
    assert load_noise_model(str(tmp_path / "old.json")).radius_correlation.independent
    for bad in ({"weight": 1.5, "width": 0.03}, {"weight": 0.3, "width": -1}, 7):
        doc["radius_correlation"] = bad
        (tmp_path / "bad.json").write_text(json.dumps(doc))
        with pytest.raises(ConfigError, match=r"measurement\.noise_model"):
            load_noise_model(str(tmp_path / "bad.json"))
