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


NEAR = ViewCorrelation(weight=0.3, width=0.03, nearby=0.8, length_m=0.02)


def _n_eff_at(corr, dirs, at):
    """1ᵀ C⁻¹ 1 by brute force, the cameras' positions counted."""
    d = np.linalg.norm(at[:, None, :] - at[None, :, :], axis=2)
    C = corr.rho(dirs @ dirs.T) + corr.rho_near(d)
    np.fill_diagonal(C, 1.0)
    return float(np.ones(len(dirs)) @ np.linalg.solve(C, np.ones(len(dirs))))


def test_a_view_from_where_one_was_taken_adds_almost_nothing(rng):
    """Two views from one camera position share the nugget's nearby part too: ρ0 = w + (1 - w)a,
    and the repeat is worth (1 - ρ0)/(1 + ρ0) of a fresh view; from far away (or with no
    positions given) the views count by their directions alone; in general the share is what
    the view adds to 1ᵀ C⁻¹ 1 with both kernels, and C stays positive definite."""
    e, c = _unit([-1.0, 0.2, 0.1]), np.array([0.2, 0.05, 0.3])
    rho0 = NEAR.weight + (1.0 - NEAR.weight) * NEAR.nearby
    held = new_view_share(NEAR, np.array([e]), e, np.array([c]), c)[0]
    assert held == pytest.approx((1.0 - rho0) / (1.0 + rho0)) and held < 0.1
    by_direction = new_view_share(NEAR, np.array([e]), e)[0]
    assert by_direction == pytest.approx((1.0 - NEAR.weight) / (1.0 + NEAR.weight))
    assert new_view_share(NEAR, np.array([e]), e, np.array([c + [0.0, 1.0, 0.0]]), c)[0] == pytest.approx(
        by_direction, rel=1e-9
    )
    one = (np.array([e]), e, np.array([c]))
    shares = [new_view_share(NEAR, *one, c + [0, 0, z])[0] for z in (0.0, 0.01, 0.03)]
    assert shares[0] < shares[1] < shares[2] < by_direction  # the farther, the more it adds
    for _ in range(20):
        k = int(rng.integers(1, 8))
        dirs = np.array([_unit(rng.normal(size=3) * 0.1 + [-1, 0, 0]) for _ in range(k + 1)])
        at = c + rng.normal(0.0, 0.01, (k + 1, 3))
        share = new_view_share(NEAR, dirs[:k], dirs[k], at[:k], at[k])[0]
        expected = _n_eff_at(NEAR, dirs, at) - _n_eff_at(NEAR, dirs[:k], at[:k])
        assert share == pytest.approx(expected, rel=1e-7, abs=1e-9)
    many = c + rng.normal(0.0, 0.005, (40, 3))
    dirs = np.array([_unit(rng.normal(size=3) * 0.05 + [-1, 0, 0]) for _ in range(40)])
    d = np.linalg.norm(many[:, None] - many[None], axis=2)
    C = NEAR.rho(dirs @ dirs.T) + NEAR.rho_near(d)
    np.fill_diagonal(C, 1.0)
    assert np.linalg.eigvalsh(C)[0] >= (1.0 - NEAR.weight) * (1.0 - NEAR.nearby) - 1e-9
    with pytest.raises(ValueError, match="camera positions"):
        new_view_share(NEAR, dirs[:3], e, many[:2], c)
    for bad in ({"nearby": 1.0}, {"nearby": -0.1}, {"length_m": 0.0}, {"length_m": math.nan}):
        with pytest.raises(ValueError, match="view correlation"):
            ViewCorrelation(0.3, 0.03, **bad)


def test_the_share_gradients_in_direction_and_position_match_finite_differences(rng):
    from bve_mj.estimation.view_correlation import TakenViews

    for _ in range(20):
        dirs = np.array([_unit(rng.normal(size=3) * 0.2 + [-1, 0, 0]) for _ in range(3)])
        at = rng.normal(0.0, 0.02, (3, 3))
        views = TakenViews.of(NEAR, dirs, at)
        e, c = _unit(rng.normal(size=3) * 0.2 + [-1, 0, 0]), rng.normal(0.0, 0.02, 3)
        _, de, dc = views.share_at(e, c)
        fd_e = finite_difference(lambda v, t=views, p=c: t.share_at(v, p)[0], e, h=1e-7)
        fd_c = finite_difference(lambda p, t=views, v=e: t.share_at(v, p)[0], c, h=1e-8)
        np.testing.assert_allclose(de(), fd_e, rtol=1e-5, atol=1e-8)
        np.testing.assert_allclose(dc(), fd_c, rtol=1e-4, atol=1e-6)
    _, _, dc = TakenViews.of(NEAR, dirs[:1], at[:1]).share_at(dirs[0], at[0])
    np.testing.assert_allclose(dc(), 0.0, atol=1e-12)  # smooth where the view was taken: a flat top


def test_twin_views_fit_the_nearby_part(rng):
    """:func:`fit_nearby` recovers (a, ℓ) from correlations the model makes; the table of
    :func:`twin_correlations` holds the correlation of pairs drawn with it, per displacement,
    one outlying fit in ten notwithstanding."""
    from bve_mj.campaigns.twin_views import TwinCorrelation, fit_nearby, twin_correlations

    truth = ViewCorrelation(0.25, 0.04, nearby=0.75, length_m=0.018)
    deltas = (0.0, 0.002, 0.005, 0.01, 0.02, 0.04)
    cos = [math.cos(d / 0.25) for d in deltas]
    table = [
        TwinCorrelation(d, 300, cs, *(2 * [float(truth.rho(np.array(cs)) + truth.rho_near(np.array(d)))]))
        for d, cs in zip(deltas, cos, strict=True)
    ]
    for name in ("centre", "radius"):
        fit = fit_nearby(table, ViewCorrelation(0.25, 0.04), name)
        assert fit.nearby == pytest.approx(0.75, abs=2e-3) and fit.length_m == pytest.approx(0.018, rel=1e-2)
    with pytest.raises(ValueError, match="at least 3"):
        fit_nearby(table[:2], truth, "centre")
    # twins that correlate no more near than far (few pairs): a valid model, not a crash
    flat = [TwinCorrelation(d, 20, 0.999, 0.3, 0.3) for d in deltas]
    assert 1e-4 <= fit_nearby(flat, ViewCorrelation(0.3, 0.03), "centre").length_m <= 1.0
    rows = []
    for d, cs in zip(deltas, cos, strict=True):
        r = float(truth.rho(np.array(cs)) + truth.rho_near(np.array(d)))
        L = np.linalg.cholesky(np.array([[1.0, r], [r, 1.0]]))
        for _ in range(2000):
            z = L @ rng.standard_normal((2, 3))  # (view, twin) x (u, v, alpha)
            if rng.random() < 0.1:
                z[0, :] += 30.0 * rng.standard_normal(3)  # a gross error of the view alone
            rows.append({"delta_m": d, "cos": cs, "errors": z[0].tolist(), "twin_errors": z[1].tolist(),
                         "radius_px": 40.0 + 10.0 * rng.random()})  # fmt: skip
    for t, d, cs in zip(twin_correlations(rows), deltas, cos, strict=True):
        expected = float(truth.rho(np.array(cs)) + truth.rho_near(np.array(d)))
        assert t.delta_m == d and t.pairs == 2000
        assert t.centre == pytest.approx(expected, abs=0.08) and t.radius == pytest.approx(expected, abs=0.1)


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
    not 5; independent views give 5; with the nearby part (one camera position: ρ0 = w + (1 -
    w)a = 0.86) 5 / (1 + 4ρ0) = 1.1."""
    k, c = np.array([0.45, 0.0, 0.2, 0.03]), np.array([0.2, 0.0, 0.3])
    model = BearingSizeModel(c, camera_rotation(c, k[:3]), np.diag([1e-6, 1e-6, 1e-6]))
    z = model.predict(k)
    prior = Belief(k, np.diag([0.05**2] * 3 + [0.01**2]))
    H = model.jacobian(k)
    prior_info = np.linalg.inv(H @ prior.cov @ H.T)
    cfg = FilterConfig(gate_probability=None, process_sigma_m=0.0)
    rho0 = NEAR.weight + (1.0 - NEAR.weight) * NEAR.nearby  # one place: the nearby part shared too
    cases = ((None, 5.0), ((CORR, CORR), 5.0 / (1 + 4 * CORR.weight)), ((NEAR, NEAR), 5.0 / (1 + 4 * rho0)))
    for corr, n_eff in cases:
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

    def counting(cls, c, directions, positions=None):
        made.append(len(directions))
        return of(cls, c, directions, positions)

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
    near = (ViewCorrelation(0.3, 0.03, 0.8, 0.02), ViewCorrelation(0.5, 0.08, 0.7, 0.03))
    with_places = ViewShares(*near)
    taken, at, c = fruits[1], rng.normal(0.0, 0.01, (2, 3)), rng.normal(0.0, 0.01, 3)
    expected = tuple(vc.TakenViews.of(x, taken, at).share(e, c)[0] for x in near)
    assert with_places(taken, e, at, c) == expected != with_places(taken, e)  # the cameras counted


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


def test_the_paper_prior_counts_a_repeated_view_as_the_share_it_adds():
    """With Σo the planner's own fusion of the views planned (the paper's eq. 9, ``prior_source =
    views``), a view is added as the objective expects it: a camera that holds where a view
    was just fused adds almost nothing (it used to add a whole fresh view each time, so the
    planner believed in the views it repeated and held still); from elsewhere, most of one."""
    from bve_mj.config import Settings, with_overrides
    from bve_mj.config.experiments import EXPERIMENTS
    from bve_mj.planning.bve import BvePlanner

    s = with_overrides(Settings(), measurement={"kind": "range"}, filter={"state": "centre_radius"})
    e = EXPERIMENTS["E3"]
    planner = BvePlanner(s, e.loss, e.constraints)
    assert s.prior_source == "views" and isinstance(planner.info, SizeInformation)
    k = np.array([0.45, 0.0, 0.2, 0.03])
    belief = Belief(k, np.diag([0.02**2] * 3 + [0.004**2]))
    c = np.array([0.2, 0.0, 0.3])

    def added(p_camera):
        before = planner.prior_precision(belief).copy()
        planner.commit(ViewPlan(p_camera, k[:3], "optimal", True, 0.0), belief)
        return float(np.trace(planner.prior_precision(belief) - before))

    first = added(c)
    planner.note_fused_view(c, k[:3])
    assert added(c + [0.0, 0.0, 1e-4]) < 0.1 * first  # held: (1 - ρ0)/(1 + ρ0) ~ 0.06, not 1 (or 0.48)
    assert added(c + [0.0, 0.12, -0.05]) > 0.3 * first  # 13 cm away, from 25° off


def test_a_view_brings_the_innovation_scale_the_share_of_its_dimension_it_adds():
    """A discounted view's NIS is computed with the variance its share inflates: it brings
    2Δc + Δr degrees of freedom (Δr alone for the apparent size; a model without the
    discount its dimension), so views from one place count in the claim's innovation scale
    as the share they add, not as whole views."""
    from bve_mj.estimation.models import CameraModel, SizeModel
    from bve_mj.estimation.view_correlation import shared_dof

    c, k = np.array([0.2, 0.0, 0.3]), np.array([0.45, 0.0, 0.2])
    assert shared_dof(BearingSizeModel(c, camera_rotation(c, k), np.eye(3)), 3, 0.5, 0.25) == 1.25
    assert shared_dof(SizeModel(c, 1e-6), 1, 0.5, 0.25) == 0.25
    assert shared_dof(CameraModel(c, camera_rotation(c, k), np.eye(3)), 3, 0.5, 0.25) == 3.0
