"""The calibrated noise model: its fit recovers a known noise, its file is validated, the
calibration renders real detections; and the claims an episode makes beside its filter."""

import json
import math

import numpy as np
import pytest

from bve_mj.cli import main
from bve_mj.config import CameraConfig
from bve_mj.errors import ConfigError
from bve_mj.estimation import Belief
from bve_mj.estimation.measure import measure
from bve_mj.estimation.noise import FEATURES, load_noise_model
from bve_mj.estimation.noise_fit import fit_noise_model
from bve_mj.geometry import camera_rotation
from bve_mj.loop.claims import Claims
from bve_mj.loop.episode import StopRules, ViewRecord
from bve_mj.loop.events import Event


def _synthetic_rows(rng, fruits=40, views=12, offset_rel=None):
    """Calibration rows whose errors follow a known model: a per-view variance
    0.3·fit² + 0.02·partial² [px²], an apparent-radius bias -0.2 - 0.5·r/100 px, and each
    fruit's own world offset N(0, (0.005 r)²) per axis (``offset_rel(n)``·r for a fruit
    whose views see a neighbour on a share n of its rim, drawn per fruit, when given)."""
    f = CameraConfig().focal_px
    rows = []
    for k in range(fruits):
        truth = np.array([0.45, 0.0, 0.2]) + rng.normal(0, 0.05, 3)
        radius = rng.uniform(0.024, 0.033)
        neighbour = rng.uniform(0.0, 0.6) if offset_rel is not None else 0.0
        offset = rng.normal(0.0, (0.005 if offset_rel is None else offset_rel(neighbour)) * radius, 3)
        for v in range(views):
            d = rng.normal(size=3) * np.array([1.0, 0.6, 0.6]) - np.array([2.0, 0.0, 0.0])
            c = truth + rng.uniform(0.15, 0.4) * d / np.linalg.norm(d)
            R = camera_rotation(c, truth)
            rho = float(np.linalg.norm(truth - c))
            r_px = f * math.tan(math.asin(radius / rho))
            arc, fit = rng.uniform(180, 360), rng.uniform(0.12, 0.5)
            sigma = math.sqrt(0.3 * fit**2 + 0.02 * ((1 - arc / 360) * r_px / 10) ** 2)
            shift = f / rho * (R.T @ offset)
            rows.append({
                "scenario": "synthetic", "scene_seed": k, "view": v, "detected": True,
                "radius_px": r_px, "arc_deg": arc, "centre_fit_px": fit, "radius_fit_px": fit,
                "fruit_shape_index": 0.9, "distance_m": rho, "camera_rotation": R.tolist(),
                "true_radius_m": radius, "camera_position_m": c.tolist(), "truth_m": truth.tolist(),
                "neighbour_share": neighbour,
                "err_u_px": shift[1] + rng.normal(0, sigma), "err_v_px": shift[2] + rng.normal(0, sigma),
                "err_alpha_px": -0.2 - 0.5 * r_px / 100 + rng.normal(0, math.sqrt(0.25 * fit**2)),
            })  # fmt: skip
    return rows


def test_the_views_tail_is_fitted_to_the_rows_the_tracker_fuses(rng):
    """The model from the target's rows; the outlier mixture from ``outlier_rows`` (the
    every-fruit detector's), normalised by that model: a tenth of them err 8x (their own
    error: each fruit's offset is taken out first). Without such rows the target's, which
    have no tail here."""
    target = _synthetic_rows(rng)
    every = _synthetic_rows(rng)
    for r in every:
        r["source"] = "every"
        if rng.random() < 0.1:  # the view's own noise 8x: 63 times its variance added
            partial = (1 - r["arc_deg"] / 360) * r["radius_px"] / 10
            sigma = math.sqrt(0.3 * r["centre_fit_px"] ** 2 + 0.02 * partial**2)
            r["err_u_px"] += rng.normal(0, math.sqrt(63) * sigma)
            r["err_v_px"] += rng.normal(0, math.sqrt(63) * sigma)
            r["err_alpha_px"] += rng.normal(0, math.sqrt(63 * 0.25) * r["radius_fit_px"])
    model, _ = fit_noise_model(target, CameraConfig(), "test", every)
    assert model.outlier_share == pytest.approx(0.1, abs=0.03)
    assert model.outlier_scale == pytest.approx(8.0, rel=0.2)
    alone, _ = fit_noise_model(target, CameraConfig(), "test")
    assert alone.outlier_share < 0.03 or alone.outlier_scale < 1.5
    assert alone.centre_var_px2 == model.centre_var_px2  # the model itself is the target's


def test_the_fit_recovers_a_known_noise(rng):
    model, report = fit_noise_model(_synthetic_rows(rng), CameraConfig(), "test")
    fit_coef, partial = model.centre_var_px2[1], model.centre_var_px2[2]
    assert fit_coef == pytest.approx(0.3, rel=0.25) and partial == pytest.approx(0.02, rel=0.35)
    assert model.radius_var_px2[1] == pytest.approx(0.25, rel=0.2)
    assert model.radius_bias_px[0] == pytest.approx(-0.2, abs=0.06)
    assert model.radius_bias_px[1] == pytest.approx(-0.5, abs=0.1)
    # the offsets are Gaussian here: their 3σ bound is a little over their σ (0.5% of r)
    h, v = model.centre_bias_rel
    assert 0.003 < h < 0.009 and 0.003 < v < 0.009
    assert report["centre"]["z_rms"] == pytest.approx(1.0, abs=0.05)
    assert report["gross_errors"] == 0
    assert model.refusal_scale == 0.0  # no view refused: nothing to learn from refusals


def test_the_fit_recovers_how_errors_grow_with_the_refusals(rng):
    """Fruits refused in a share ρ of their views err exp(1.5 ρ) times the variance: the fit
    finds b = 1.5, and b = 0 when the refusals say nothing."""
    rows = _synthetic_rows(rng, fruits=80, views=12)
    share = {k: rng.uniform(0.0, 0.75) for k in range(80)}
    grown, flat = [], []
    for r in rows:
        rho = share[r["scene_seed"]]
        s = math.exp(0.5 * 1.5 * rho)
        bias = -0.2 - 0.5 * r["radius_px"] / 100
        grown.append({**r, "err_u_px": s * r["err_u_px"], "err_v_px": s * r["err_v_px"],
                      "err_alpha_px": bias + s * (r["err_alpha_px"] - bias)})  # fmt: skip
        flat.append(r)
    for k, rho in share.items():
        refused = {"scenario": "synthetic", "scene_seed": k, "detected": False}
        grown += [refused] * round(12 * rho / (1 - rho))
        flat += [refused] * round(12 * rho / (1 - rho))
    model, report = fit_noise_model(grown, CameraConfig(), "test")
    assert model.refusal_scale == pytest.approx(1.5, abs=0.5)
    assert report["refusal_fruits"] == 80
    assert fit_noise_model(flat, CameraConfig(), "test")[0].refusal_scale < 0.5


def test_the_fit_learns_the_fruits_own_offset_from_what_the_detector_saw(rng):
    """Fruits whose rim a neighbour hides on a share n err by an own offset of σ (0.1% +
    1.5%·n) of the radius: the conditioned fit puts it on the neighbour term, so a fruit
    alone claims a small offset and one with neighbours on half its rim a large one, each
    about its σ (the 97.1% bound over 3σ: a little over it); the bound over all fruits lies
    between."""
    from bve_mj.estimation.noise import Outline

    rows = _synthetic_rows(rng, fruits=120, views=10, offset_rel=lambda n: 0.001 + 0.015 * n)
    model, _ = fit_noise_model(rows, CameraConfig(), "test")
    assert len(model.centre_offset_terms) == 3 and model.centre_offset_terms[2] > 0.0

    def sigma_rel(neighbour):
        cov = model.centre_offset_cov(0.03, 0.9, [Outline(neighbour)] * 3)
        return math.sqrt(np.trace(cov) / 3) / 0.03

    whole, half = sigma_rel(0.0), sigma_rel(0.5)
    assert whole < 0.004 and 0.006 < half < 0.014
    h, v = model.centre_bias_rel
    assert whole < math.sqrt((2 * h * h + v * v) / 3) < half
    # what was seen not known (or not in every view fused): the bound over all fruits
    np.testing.assert_array_equal(
        model.centre_offset_cov(0.03, 0.9, [Outline(), None]), model.centre_bias_cov(0.03)
    )


@pytest.mark.parametrize("heavy", [False, True])
def test_the_claims_tail_scale_holds_the_errors_tail(rng, heavy):
    """Gaussian errors need no tail scale (κ² ≈ 1: 1.0-1.7 over seeds, the bootstrap's upper
    bound); a few fruits (one in forty, fewer than the offset's 97.1% bound leaves out) off
    by eight times the others' own offset, the same in every view of them, need one (8-9
    over seeds): their views agree,
    so the innovations cannot show it, and κ² grows until the χ²₃ 99.9% ellipsoid of what
    an episode of 3-6 of the views would claim holds 99.9% of such episodes' errors. (Errors
    a fruit's views disagree on, each view four times too large, the innovations show: no
    tail scale needed for them.)"""
    rows = _synthetic_rows(rng, fruits=120, views=12)
    if heavy:  # one fruit in forty is off by 4% of its radius in the world: every view agrees
        f = CameraConfig().focal_px
        shifts = {k: rng.normal(0.0, 0.04, 3) for k in range(0, 120, 40)}
        out = []
        for r in rows:
            off = shifts.get(r["scene_seed"])
            if off is not None:
                shift = (
                    f / r["distance_m"] * (np.asarray(r["camera_rotation"]).T @ (off * r["true_radius_m"]))
                )
                r = {**r, "err_u_px": r["err_u_px"] + shift[1], "err_v_px": r["err_v_px"] + shift[2]}
            out.append(r)
        rows = out
    model, _ = fit_noise_model(rows, CameraConfig(), "test")
    shape = model.claim_shape
    if heavy:
        assert model.tail_scale > 3.0
        # the second moment is far inside the tail: a Student-t claim of few dof
        assert shape.bound_scale > 2.0 and shape.dof < 10.0
    else:
        assert 1.0 <= model.tail_scale < 2.0
        assert shape.bound_scale < 2.0  # nearly Gaussian
    assert 0.0 < model.moment_scale <= model.tail_scale
    assert model.view_tail_scale >= 1.0  # single views' (size-only episodes claim with it)
    assert 0.0 < model.view_moment_scale <= model.view_tail_scale


def test_the_radius_second_moment_is_its_own(rng):
    """m_r is the radius' squared error over its claimed variance in the episode-like draws:
    where the σ the model gives the apparent radius is twice its errors' it falls nearly
    threefold (0.35-0.38 of it over five seeds: not fourfold, as the smaller radius residuals
    also lower the innovation scale) while the centre's m moves by 4-8%. With the σ the rows
    were drawn with it is 1.05-1.68, above 1: the claim's innovation scale, from 3-6 views and
    its prior's 6 dof, is below 1 on average (0.80 here; 0.83-0.97 in the loop's own episodes)."""
    from dataclasses import replace

    from bve_mj.estimation.noise_tail import episode_tails

    rows = _synthetic_rows(rng, fruits=60, views=8)
    model = replace(load_noise_model("default"), radius_bias_px=(-0.2, -0.5))  # the rows' bias

    def drawn(r, radius_factor=1.0):
        partial = (1 - r["arc_deg"] / 360) * r["radius_px"] / 10
        centre = math.sqrt(0.3 * r["centre_fit_px"] ** 2 + 0.02 * partial**2)
        return centre, radius_factor * math.sqrt(0.25 * r["radius_fit_px"] ** 2)

    f = CameraConfig().focal_px
    honest = episode_tails(rows, [], model, f, drawn)
    wide = episode_tails(rows, [], model, f, lambda r: drawn(r, 2.0))
    assert 0.8 < honest.radius_moment_scale < 2.2
    assert 0.25 < wide.radius_moment_scale / honest.radius_moment_scale < 0.5
    assert wide.moment_scale == pytest.approx(honest.moment_scale, rel=0.25)


def test_the_tail_draws_are_per_fruit_and_are_what_the_tails_are_fitted_on(rng):
    """``episode_draws`` gives each calibration fruit of 4 views or more its own draws, and
    ``episode_tails``' moments are their means: a fruit whose errors are made five times
    larger stands out in its own draws (``benchmarks/claim_moments.py --groups`` reads them
    so) and raises the moment scale."""
    from bve_mj.estimation.noise_tail import TAIL_DRAWS, episode_draws, episode_tails, fruit_key

    rows = _synthetic_rows(rng, fruits=30, views=6)
    model = load_noise_model("default")

    def sigmas(r):
        return model.sigmas_px(r["radius_px"], r["arc_deg"], r["centre_fit_px"], r["radius_fit_px"], 0.9)

    f = CameraConfig().focal_px
    draws = episode_draws(rows, [], model, f, sigmas)
    assert set(draws) == {fruit_key(r) for r in rows} and len(draws) == 30
    assert all(len(n) == len(rn) == TAIL_DRAWS for n, rn in draws.values())
    tails = episode_tails(rows, [], model, f, sigmas)
    mean = float(np.mean([n for n, _ in draws.values()])) / 3.0
    assert tails.moment_scale == pytest.approx(min(mean, tails.tail_scale))
    assert tails.radius_moment_scale == pytest.approx(float(np.mean([rn for _, rn in draws.values()])))
    bad = fruit_key(rows[0])
    worse = [
        {**r, "err_u_px": 5.0 * r["err_u_px"], "err_v_px": 5.0 * r["err_v_px"]} if fruit_key(r) == bad else r
        for r in rows
    ]
    worse_draws = episode_draws(worse, [], model, f, sigmas)
    others = [np.mean(n) for k, (n, _) in worse_draws.items() if k != bad]
    assert np.mean(worse_draws[bad][0]) > 5.0 * np.median(others)
    assert episode_tails(worse, [], model, f, sigmas).moment_scale > tails.moment_scale


def test_the_tail_draws_count_views_from_one_place_as_the_share_they_add(rng):
    """Fruits whose views come in twins (two views 1 mm apart, one error: a view from one
    place repeats its error): an episode-like draw that counts the twin as a fresh view
    claims too little, and κ² grows to hold its errors; counted as the share it adds (the
    model's nearby correlation, by the cameras' positions), as the loop counts it, the claim
    needs less (κ² 6.3-7.9 against 8.3-10.9 over five seeds: 0.67-0.78 of it)."""
    from dataclasses import replace

    from bve_mj.estimation.noise_tail import episode_tails
    from bve_mj.estimation.view_correlation import ViewCorrelation

    rows = []
    for r in _synthetic_rows(rng, fruits=60, views=3):
        twin = {**r, "view": r["view"] + 100}
        twin["camera_position_m"] = (np.asarray(r["camera_position_m"]) + [0.0, 0.001, 0.0]).tolist()
        rows += [r, twin]
    rows = [{**r, "err_u_px": 3.0 * r["err_u_px"], "err_v_px": 3.0 * r["err_v_px"]} for r in rows]
    model = load_noise_model("default")

    def sigmas(r):
        return model.sigmas_px(r["radius_px"], r["arc_deg"], r["centre_fit_px"], r["radius_fit_px"], 0.9)

    def apart(c: ViewCorrelation) -> ViewCorrelation:
        return replace(c, nearby=0.0)

    far = replace(model, centre_correlation=apart(model.centre_correlation),
                  radius_correlation=apart(model.radius_correlation))  # fmt: skip
    f = CameraConfig().focal_px
    near_scale, far_scale = (
        episode_tails(rows, [], model, f, sigmas)[0],
        episode_tails(rows, [], far, f, sigmas)[0],
    )
    assert far_scale > 1.0
    assert near_scale < 0.85 * far_scale


def test_a_view_of_the_wrong_fruit_is_a_gross_error_not_noise(rng):
    rows = _synthetic_rows(rng)
    clean, _ = fit_noise_model(rows, CameraConfig(), "test")
    rows[5] = {**rows[5], "err_u_px": 40.0, "err_v_px": -25.0}  # a neighbour measured
    model, report = fit_noise_model(rows, CameraConfig(), "test")
    assert report["gross_errors"] == 1
    assert model.centre_var_px2[1] == pytest.approx(clean.centre_var_px2[1], rel=0.05)


def test_measure_removes_the_bias_and_gives_the_models_variance():
    model = load_noise_model("default")

    class Det:  # a detection as the detector reports it
        bearing_camera = np.array([0.99, 0.1, -0.05]) / np.linalg.norm([0.99, 0.1, -0.05])
        radius_px, arc_deg, centre_fit_px, radius_fit_px = 60.0, 300.0, 0.2, 0.2
        angular_radius_rad = 0.12

    f = CameraConfig().focal_px
    z, R = measure(Det(), model, 0.9, f)
    a = Det.bearing_camera
    assert z[:2] == pytest.approx([a[1] / a[0], a[2] / a[0]])
    assert z[2] == pytest.approx(0.12 - model.radius_bias(60.0) / f)
    sc, sr = model.sigmas_px(60.0, 300.0, 0.2, 0.2, 0.9)
    assert np.sqrt(np.diag(R)) * f == pytest.approx([sc, sc, sr])


def test_the_shipped_model_loads_and_says_what_it_is():
    model = load_noise_model("default")
    model.check_camera(CameraConfig(), "default")
    assert model.samples > 1000 and "bve-mj calibrate" in model.source
    assert model.radius_bias(60.0) < 0.0  # the mask sees the fruit smaller than it is
    assert model.refusal_scale > 0.0  # hard fruits (often refused) err more
    assert model.tail_scale >= 1.0
    assert model.centre_offset_terms  # the fruit's offset from what the detector saw


def test_a_model_file_from_before_the_refusal_scale_loads_with_none(tmp_path):
    data = load_noise_model("default").to_json()
    del data["refusal_scale"]
    path = tmp_path / "old.json"
    path.write_text(json.dumps(data))
    assert load_noise_model(str(path)).refusal_scale == 0.0
    path.write_text(json.dumps({**data, "refusal_scale": -1.0}))
    with pytest.raises(ConfigError, match="refusal_scale"):
        load_noise_model(str(path))


def test_a_model_file_from_before_the_conditioned_offset_loads_with_the_bound_over_all_fruits(tmp_path):
    from bve_mj.estimation.noise import Outline

    data = load_noise_model("default").to_json()
    old = {k: v for k, v in data.items() if k != "centre_offset_terms"}
    path = tmp_path / "v3.json"
    path.write_text(json.dumps({**old, "version": 3}))
    model = load_noise_model(str(path))
    assert model.centre_offset_terms == ()
    cov = model.centre_offset_cov(0.03, 0.9, [Outline(0.1)] * 3)
    np.testing.assert_array_equal(cov, model.centre_bias_cov(0.03))
    for bad in ([-1.0, 0.0, 0.0], [1e-4, 1e-4], [float("nan")] * 3, "many"):
        path.write_text(json.dumps({**data, "centre_offset_terms": bad}))
        with pytest.raises(ConfigError, match="noise_model"):
            load_noise_model(str(path))


def test_a_model_file_from_before_the_scale_neighbour_and_tail_terms_loads_without_them(tmp_path):
    new = load_noise_model("default")
    data = new.to_json()
    old = {**data, "version": 2, "features": list(FEATURES[:4])}
    old["centre_var_px2"], old["radius_var_px2"] = data["centre_var_px2"][:4], data["radius_var_px2"][:4]
    del old["tail_scale"]
    path = tmp_path / "old.json"
    path.write_text(json.dumps(old))
    model = load_noise_model(str(path))
    assert model.centre_var_px2 == (*new.centre_var_px2[:4], 0.0, 0.0, 0.0, 0.0) and model.tail_scale == 1.0
    for bad in ({**data, "tail_scale": 0.5}, {**data, "features": ["floor", "scale"]}):
        path.write_text(json.dumps(bad))
        with pytest.raises(ConfigError, match="noise_model"):
            load_noise_model(str(path))


def test_the_planners_noise_of_a_view_not_taken_is_the_models():
    """The BVE's variance a + b·T² of a whole fruit seen at apparent radius f·T is what the
    noise model gives a detection of it with the typical fit: every term that grows with
    the apparent radius (elongation, scale, the close view's) included."""
    from bve_mj.config.settings import load_settings
    from bve_mj.planning.size_information import size_information

    settings = load_settings("examples/scenarios/suite/plum.toml")
    model, f = load_noise_model("default"), settings.camera.focal_px
    info = size_information(settings)
    for T in (0.05, 0.1, 0.2):
        sc, sr = model.expected_sigmas_px(f * T, settings.fruit.shape_index)
        for var, sigma in ((info.bearing_var, sc), (info.size_var, sr)):
            assert math.sqrt(var[0] + var[1] * T**2 + var[2] * T**4) * f == pytest.approx(sigma)


@pytest.mark.parametrize(
    ("content", "reason"),
    [
        (None, "readable"),
        ("{not json", "JSON"),
        ('{"kind": "something else"}', "written by bve-mj calibrate"),
    ],
)
def test_a_bad_noise_model_file_is_a_config_error(tmp_path, content, reason):
    path = tmp_path / "model.json"
    if content is not None:
        path.write_text(content)
    with pytest.raises(ConfigError, match=reason) as err:
        load_noise_model(str(path))
    assert "measurement.noise_model" in str(err.value)


def test_a_model_for_another_camera_is_refused(tmp_path):
    doc = load_noise_model("default").to_json()
    doc["width_px"] = 1280
    path = tmp_path / "other.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(ConfigError, match="calibrated for this camera"):
        load_noise_model(str(path)).check_camera(CameraConfig(), str(path))


@pytest.mark.parametrize(
    "content", [None, "{broken", '{"kind": "bve_mj detector noise model", "version": 1}']
)
def test_episode_with_a_bad_noise_model_exits_2_naming_it(tmp_path, capsys, content):
    model = tmp_path / "model.json"
    if content is not None:
        model.write_text(content)
    config = tmp_path / "scenario.toml"
    config.write_text(f'[measurement]\nnoise_model = "{model}"\n')
    assert main(["episode", "--config", str(config), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "measurement.noise_model" in err and "Traceback" not in err


def test_calibrate_renders_real_detections_and_writes_a_loadable_model(tmp_path, capsys):
    out, rows = tmp_path / "model.json", tmp_path / "rows.json"
    argv = ["calibrate", "--only", "clean", "--scenes", "3", "--views", "9", "--seed", "5", "--workers", "1"]
    assert main([*argv, "--twin-views", "6", "--out", str(out), "--json", str(rows), "--quiet"]) == 0
    model = load_noise_model(str(out))
    model.check_camera(CameraConfig(), str(out))
    doc = json.loads(rows.read_text())
    detected = [r for r in doc["rows"] if r.get("detected")]
    assert len(detected) >= 20
    # a lone red fruit seen whole: the centre within a pixel, the radius' bias negative
    assert np.median([abs(r["err_u_px"]) for r in detected]) < 1.0
    assert model.radius_bias(60.0) < 0.0
    # twins from cameras 0-40 mm away: views from one place share more than their direction says
    for corr in (model.centre_correlation, model.radius_correlation):
        assert 0.0 < corr.nearby <= 0.99 and 1e-3 < corr.length_m < 1.0
    assert "twin pairs" in model.source
    printed = capsys.readouterr().out
    assert "wrote" in printed and "views from one place share more" in printed
    # a red detector's rows fit no partial-colour terms, and the command says so
    assert model.partial_colour_offset == 0.0 and model.partial_colour_view == (0.0, 1.0, 1.0)
    assert "a detector of a class short of red: 0 views, 0 fruits, too few" in printed


@pytest.mark.parametrize(
    ("argv", "field"),
    [
        (["calibrate", "--scenes", "0"], "scenes"),
        (["calibrate", "--views", "x"], "views"),
        (["calibrate", "--out", "model.txt"], "out"),
        (["calibrate", "--twin-views", "-1"], "twin_views"),
        (["calibrate", "--only", "nowhere"], "only"),
        (["episode", "--filter", "kalman"], "filter.kind"),
        (["episode", "--state", "position"], "filter.state"),
        (["scenarios", "--filter", "particle", "--seeds", "1"], "filter.kind"),
    ],
)
def test_bad_input_exits_2_with_one_line(argv, field, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and field in err and "Traceback" not in err


# ---------------------------------------------------------------- what an episode claims
def _view(i, belief, accepted=True, events=()):
    return ViewRecord(i, np.zeros(3), None, True, 0.0, True, accepted, 1.0, belief, None, tuple(events))


def test_claims_add_the_fruits_own_offset_and_scale_by_the_innovations():
    b = Belief(np.array([0.4, 0.0, 0.2, 0.03]), np.diag([1e-6, 1e-6, 4e-6, 1e-8]))
    offset = np.diag([1e-8, 1e-8, 4e-8])
    plain = Claims(offset).claim(b, [(30.0, 3)])
    np.testing.assert_allclose(plain.cov[:3, :3], b.cov[:3, :3] + offset)
    assert plain.cov[3, 3] == b.cov[3, 3]
    # views that disagree twice as much as the noise model says: s² = (6 + 2·9) / (6 + 9)
    scaled = Claims(None, 6.0).claim(b, [(9.0, 3), (9.0, 3), (0.0, 3)])
    np.testing.assert_allclose(scaled.cov, b.cov * (6 + 18) / (6 + 9))
    assert Claims(None, 6.0).scale([]) == 1.0
    # a fruit the detector refused in half the views: exp(b / 2) on everything claimed
    hard = Claims(offset, None, 0.8).claim(b, [], refused_share=0.5)
    np.testing.assert_allclose(hard.cov, plain.cov * math.exp(0.4))
    assert Claims(offset, None, 0.8).claim(b, []).cov[0, 0] == plain.cov[0, 0]
    # heavy-tailed errors: κ² on all of it, last
    np.testing.assert_allclose(Claims(offset, None, 0.8, 2.5).claim(b, [], 0.5).cov, hard.cov * 2.5)
    # told what the detector saw: the offset from it, in place of the bound over all fruits
    seen = Claims(offset, offset_of=lambda outlines: np.eye(3) * 1e-9 * len(outlines))
    np.testing.assert_allclose(
        seen.claim(b, [], 0.0, [None, None]).cov[:3, :3], b.cov[:3, :3] + np.eye(3) * 2e-9
    )
    np.testing.assert_allclose(seen.claim(b, []).cov, plain.cov)


def test_claims_of_the_detector_carry_its_calibration():
    from bve_mj.estimation.noise import Outline, load_noise_model

    noise = load_noise_model("default")
    c = Claims.of_detector(noise, 0.03, 6.0, 0.9)
    np.testing.assert_array_equal(c.centre_offset_cov, noise.centre_bias_cov(0.03))
    seen = [Outline(0.2), Outline(0.0)]
    np.testing.assert_array_equal(c.offset_of(seen), noise.centre_offset_cov(0.03, 0.9, seen))
    # an episode of the apparent size alone: the single views' κ² and the bound over all fruits
    size_only = Claims.of_detector(noise, 0.03, 6.0, 0.9, size_only=True)
    assert size_only.tail_scale == noise.view_tail_scale and size_only.offset_of is None
    assert (c.innovation_prior_dof, c.refusal_scale, c.tail_scale) == (
        6.0,
        noise.refusal_scale,
        noise.tail_scale,
    )


def test_converged_waits_for_enough_agreeing_views():
    tight = Belief(np.zeros(3), np.eye(3) * 1e-8)
    rules = StopRules(sigma_m=0.0015, min_accepted=3)
    assert rules.outcome([_view(0, tight), _view(1, tight)]) is None
    assert rules.outcome([_view(0, tight), _view(1, tight), _view(2, tight)]) == "converged"
    # a reset starts the count again
    views = [
        _view(0, tight),
        _view(1, tight),
        _view(2, tight, events=(Event("belief_reset"),)),
        _view(3, tight),
    ]
    assert rules.outcome(views) is None
    assert StopRules(sigma_m=0.0015).outcome([_view(0, tight)]) == "converged"


def test_calibrate_says_what_the_shipped_model_claims_of_the_fruits_offset():
    """The lines ``bve-mj calibrate`` prints of the offset, for a conditioned model and an old one."""
    from bve_mj.cli.suite import offset_lines

    model = load_noise_model("default")
    lines = offset_lines(model)
    assert len(lines) == 2 and "n̄²" in lines[1] and f"{model.centre_offset_terms[2]:.3g}" in lines[1]
    from dataclasses import replace

    assert len(offset_lines(replace(model, centre_offset_terms=()))) == 1


def test_fruits_of_one_scene_are_fitted_as_separate_fruits(rng):
    """The every-fruit rows put several fruits in one scene: each fruit's own offset is its own
    (keyed by ``fruit``), so the neighbour-conditioned offset is learnt as well as with one
    fruit per scene; pooled per scene, the four fruits' offsets would average out."""
    from bve_mj.estimation.noise import Outline

    rows = _synthetic_rows(rng, fruits=120, views=10, offset_rel=lambda n: 0.001 + 0.015 * n)
    for r in rows:
        k = r["scene_seed"]
        r.update(scene_seed=k // 4, fruit=k % 4, source="every")
    model, report = fit_noise_model(rows, CameraConfig(), "test")
    assert report["fruits"] == 120

    def sigma_rel(neighbour):
        return math.sqrt(np.trace(model.centre_offset_cov(0.03, 0.9, [Outline(neighbour)] * 3)) / 3) / 0.03

    assert sigma_rel(0.0) < 0.004 and 0.006 < sigma_rel(0.5) < 0.014


def test_every_fruit_rows_match_each_detection_to_the_fruit_it_measured():
    """In one view: a detection on each of two fruits (one 2 px off), one on no fruit, a
    refusal of a third fruit and one of a fruit already measured: two measured rows with the
    right fruit and error, one refused row, nothing for the stray detection."""
    from types import SimpleNamespace

    from bve_mj.campaigns.calibration import _every_fruit_rows
    from bve_mj.perception.all_fruit import FruitDetections, Refusal
    from bve_mj.perception.detection import Intrinsics

    cam = CameraConfig()
    intrinsics = Intrinsics.from_camera(cam)
    f = intrinsics.focal_px
    p = np.array([0.0, 0.0, 0.3])
    R = camera_rotation(p, np.array([0.4, 0.0, 0.3]))
    fruits = [
        SimpleNamespace(centre_m=np.array(c), radius_m=0.03, shape_index=0.9, colour="red")
        for c in ([0.4, 0.0, 0.3], [0.42, 0.07, 0.31], [0.4, -0.08, 0.28], [-0.3, 0.0, 0.3])
    ]  # the last behind the camera

    def detection(i, shift_px=(0.0, 0.0)):
        t = R.T @ (fruits[i].centre_m - p)
        uv = intrinsics.project(t) + np.array(shift_px)
        ray = intrinsics.rays(uv)[0]
        alpha = math.asin(0.03 / np.linalg.norm(t))
        return SimpleNamespace(
            centre_px=uv, bearing_camera=ray / np.linalg.norm(ray), angular_radius_rad=alpha,
            radius_px=f * math.tan(alpha), arc_deg=300.0, trimmed_fraction=0.1, centre_fit_px=0.2,
            radius_fit_px=0.2, centre_jackknife_px=0.0, radius_jackknife_px=0.0,
            neighbour_share=0.2, centre_disagreement_px=0.0,
        )  # fmt: skip

    stray = detection(0, (200.0, 0.0))
    uv2 = detection(2).centre_px
    found = FruitDetections(
        (detection(0), detection(1, (2.0, 0.0)), stray),
        (Refusal(uv2, 40.0, "too little outline", True), Refusal(detection(0).centre_px, 40.0, "fragment")),
    )
    view = {"scenario": "s", "scene_seed": 1, "view": 3, "aim_sigma_m": 0.0, "fruit_shape_index": 0.9,
            "camera_position_m": p.tolist(), "camera_rotation": R.tolist()}  # fmt: skip
    rows = _every_fruit_rows(found, fruits, p, R, intrinsics, view)
    assert [(r["fruit"], r["detected"]) for r in rows] == [(0, True), (1, True), (2, False)]
    assert all(r["source"] == "every" and r["scene_seed"] == 1 for r in rows)
    assert abs(rows[0]["err_u_px"]) < 1e-6 and abs(rows[0]["err_alpha_px"]) < 1e-6
    # the image's u grows to the right, the camera frame's y to the left: 2 px right is -2 in u
    assert math.hypot(rows[1]["err_u_px"], rows[1]["err_v_px"]) == pytest.approx(2.0, abs=0.1)
    # the target (its own rows measure it) gives no every-fruit row
    kept = _every_fruit_rows(found, fruits, p, R, intrinsics, view, exclude=0)
    assert [(r["fruit"], r["detected"]) for r in kept] == [(1, True), (2, False)]


def test_calibrate_every_fruit_adds_the_neighbours_rows(tmp_path, capsys):
    out, rows = tmp_path / "model.json", tmp_path / "rows.json"
    argv = ["calibrate", "--only", "ripe_truss", "--scenes", "2", "--views", "12", "--every-fruit"]
    argv += ["--seed", "5", "--workers", "1", "--out", str(out), "--json", str(rows), "--quiet"]
    assert main(argv) == 0
    doc = json.loads(rows.read_text())
    every = [r for r in doc["rows"] if r.get("source") == "every"]
    assert every and all(r["fruit"] != 0 for r in every)  # neighbours, never the target again
    assert sum(r.get("source") != "every" for r in doc["rows"]) == 24
    printed = capsys.readouterr().out
    assert "its neighbours" in printed and "of views err" in printed
    model = load_noise_model(str(out))
    assert "every fruit" in model.source
    # the model is the target's rows' alone; the neighbours' fit its views' tail
    target = [r for r in doc["rows"] if r.get("source") != "every"]
    alone, _ = fit_noise_model(target, CameraConfig(), model.source)
    assert alone.centre_var_px2 == model.centre_var_px2


def test_the_claims_moment_scale_is_validated_and_read_back(tmp_path):
    """A model whose claim's second moment exceeds its tail scale is refused by name; one
    that does not give it (files made before) claims Gaussian, as before; a written model
    reads back with its shape."""
    from dataclasses import replace

    model = load_noise_model("default")
    assert 1.0 < model.claim_shape.bound_scale == pytest.approx(model.tail_scale / model.moment_scale)
    with pytest.raises(ValueError, match="moment_scale"):
        replace(model, moment_scale=2.0 * model.tail_scale)
    with pytest.raises(ValueError, match="view_moment_scale"):
        replace(model, view_moment_scale=0.0)
    assert replace(model, moment_scale=None).claim_shape.bound_scale == 1.0
    with pytest.raises(ValueError, match="radius_moment_scale"):
        replace(model, radius_moment_scale=-1.0)
    with pytest.raises(ValueError, match="radius_moment_scale"):
        replace(model, radius_moment_scale=math.nan)
    path = tmp_path / "model.json"
    path.write_text(json.dumps(model.to_json()), encoding="utf-8")
    assert load_noise_model(str(path)).claim_shape == model.claim_shape
    moments = ("moment_scale", "view_moment_scale", "radius_moment_scale")
    old = {k: v for k, v in model.to_json().items() if k not in moments}
    path.write_text(json.dumps(old), encoding="utf-8")
    assert load_noise_model(str(path)).claim_shape.bound_scale == 1.0
