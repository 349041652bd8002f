"""The own offset of fruit a detector of a class short of red fits: the fit recovers it from
calibration rows, the claim adds it only for such a detector, and the episode wires it."""

import dataclasses
import json
import pickle

import numpy as np
import pytest

from bve_mj.config import CameraConfig, DetectorConfig
from bve_mj.config.settings import load_settings
from bve_mj.errors import ConfigError
from bve_mj.estimation.noise import Outline, load_noise_model
from bve_mj.estimation.noise_fit import fit_noise_model
from bve_mj.estimation.noise_tail import row_sigmas
from bve_mj.estimation.partial_colour import (
    fit_partial_colour,
    fit_partial_colour_offset,
    fit_partial_colour_view,
    partial_colour_cov,
)
from bve_mj.loop.claims import Claims
from tests.test_calibration import _synthetic_rows


@pytest.mark.parametrize(
    ("ripe_class", "partial"),
    [(None, False), ("red", False), ("light_red", True), ("pink", True), ("turning", True), ("orange", True)],
)
def test_the_ripe_class_says_whether_the_detector_fits_fruit_coloured_in_part(ripe_class, partial):
    assert DetectorConfig(ripe_class=ripe_class).partial_colour is partial


def test_the_fit_recovers_the_offset_of_fruit_coloured_in_part(rng):
    """Red fruits' rows fit the model (offsets 0.5% of r per axis); 24 fruits of a turning
    detector have offsets 2% of r per axis more: the term fitted from them is that (a share of
    r² per axis, ~4e-4), sized so their offsets lie within the claim's 3σ; red rows give none."""
    f = CameraConfig().focal_px
    model, _ = fit_noise_model(_synthetic_rows(rng), CameraConfig(), "test")
    turning = _synthetic_rows(rng, fruits=24, offset_rel=lambda n: 0.02)
    for r in turning:
        r["ripe_class"], r["neighbour_share"] = "turning", 0.0
    share, fruits = fit_partial_colour_offset(turning, model, f)
    assert fruits == 24 and 2e-4 < share < 1.2e-3
    red = [{**r, "ripe_class": "red"} for r in turning]
    assert fit_partial_colour_offset(red, model, f) == (0.0, 0)
    assert fit_partial_colour_offset(turning[:48], model, f)[0] == 0.0  # 4 fruits: too few


def test_the_fit_recovers_the_views_bias_and_noise_of_fruit_coloured_in_part(rng):
    """Turning views see the apparent radius 0.6 px smaller than the model's bias and err with
    4 times its variance (centre and radius): the fit finds both; red rows, or too few, none."""
    f = CameraConfig().focal_px
    model, _ = fit_noise_model(_synthetic_rows(rng), CameraConfig(), "test")
    turning = _synthetic_rows(rng, fruits=20)
    for r in turning:
        sc, sr = row_sigmas(model, r)
        r["ripe_class"] = "pink"
        r["err_u_px"] += rng.normal(0, np.sqrt(3.0) * sc)
        r["err_v_px"] += rng.normal(0, np.sqrt(3.0) * sc)
        r["err_alpha_px"] += -0.6 + rng.normal(0, np.sqrt(3.0) * sr)
    (delta, k_c, k_r), views = fit_partial_colour_view(turning, model, f)
    assert views == 240 and delta == pytest.approx(-0.6, abs=0.1)
    assert k_c == pytest.approx(4.0, rel=0.3) and k_r == pytest.approx(4.0, rel=0.3)
    assert fit_partial_colour_view([{**r, "ripe_class": "red"} for r in turning], model, f)[0] == (
        0.0,
        1.0,
        1.0,
    )
    assert fit_partial_colour_view(turning[:29], model, f)[0] == (0.0, 1.0, 1.0)
    viewed = dataclasses.replace(model, partial_colour_view=(delta, k_c, k_r)).for_partial_colour()
    r = turning[0]
    sc, sr = row_sigmas(model, r)
    assert row_sigmas(viewed, r) == pytest.approx((sc * np.sqrt(k_c), sr * np.sqrt(k_r)))
    assert viewed.radius_bias(50.0) == pytest.approx(model.radius_bias(50.0) + delta)
    assert viewed.partial_colour_view == (0.0, 1.0, 1.0)  # applied once


def test_calibrate_fits_both_terms_from_its_own_rows_and_none_from_red_ones(rng):
    """What ``bve-mj calibrate`` fits last (``fit_partial_colour``): from rows of a turning
    detector whose views err 0.6 px small and whose fruits are offset 2% of r, the views'
    bias and then, under it, the offset; from red rows none, though the model held terms."""
    f = CameraConfig().focal_px
    model, _ = fit_noise_model(_synthetic_rows(rng), CameraConfig(), "test")
    turning = _synthetic_rows(rng, fruits=24, offset_rel=lambda n: 0.02)
    for r in turning:
        r["ripe_class"], r["neighbour_share"] = "turning", 0.0
        r["err_alpha_px"] -= 0.6
    fitted, views, fruits = fit_partial_colour(turning, model, f)
    assert (views, fruits) == (288, 24)
    assert fitted.partial_colour_view[0] == pytest.approx(-0.6, abs=0.1)
    assert 2e-4 < fitted.partial_colour_offset < 1.2e-3
    red = [{**r, "ripe_class": "red"} for r in turning]
    none, views, fruits = fit_partial_colour(red, fitted, f)
    assert (views, fruits) == (0, 0)
    assert none.partial_colour_view == (0.0, 1.0, 1.0) and none.partial_colour_offset == 0.0


def test_a_detector_short_of_red_claims_the_caps_offset_and_a_red_one_as_before():
    noise = load_noise_model("default")
    assert noise.partial_colour_offset > 0.0  # the shipped model carries it
    extra = partial_colour_cov(noise, 0.03)
    h, v = noise.centre_bias_rel
    assert extra[2, 2] > extra[0, 0] > 0.0 and extra[2, 2] / extra[0, 0] == pytest.approx((v / h) ** 2)
    assert np.trace(extra) / 3 == pytest.approx(noise.partial_colour_offset * 0.03**2)
    red = Claims.of_detector(noise, 0.03, 6.0, 0.9)
    turning = Claims.of_detector(noise, 0.03, 6.0, 0.9, partial_colour=True)
    seen = [Outline(0.0), Outline(0.3)]
    np.testing.assert_array_equal(red.offset_of(seen), noise.centre_offset_cov(0.03, 0.9, seen))
    np.testing.assert_allclose(turning.offset_of(seen), red.offset_of(seen) + extra)
    np.testing.assert_allclose(turning.centre_offset_cov, noise.centre_bias_cov(0.03) + extra)
    again = pickle.loads(pickle.dumps(turning))  # a spawned worker's claims travel
    np.testing.assert_array_equal(again.offset_of(seen), turning.offset_of(seen))
    size_only = Claims.of_detector(noise, 0.03, 6.0, 0.9, size_only=True, partial_colour=True)
    np.testing.assert_allclose(size_only.centre_offset_cov, noise.centre_bias_cov(0.03) + extra)


def test_a_model_file_without_the_terms_loads_with_none_and_bad_ones_are_refused(tmp_path):
    data = load_noise_model("default").to_json()
    path = tmp_path / "old.json"
    old = {k: v for k, v in data.items() if k not in ("partial_colour_offset", "partial_colour_view")}
    path.write_text(json.dumps(old))
    model = load_noise_model(str(path))
    assert model.partial_colour_offset == 0.0 and model.partial_colour_view == (0.0, 1.0, 1.0)
    for key, bad in (("partial_colour_offset", -1e-5), ("partial_colour_view", [0.0, -1.0, 1.0])):
        path.write_text(json.dumps({**data, key: bad}))
        with pytest.raises(ConfigError, match=key):
            load_noise_model(str(path))


def test_an_episode_whose_detector_wants_turning_fruit_claims_the_caps_offset():
    from bve_mj.loop.mujoco import episode_parts
    from bve_mj.loop.start import start_episode

    noise, seen = load_noise_model("default"), [Outline(0.0)] * 3
    for name, partial in (("turning", True), ("clean", False)):
        settings = load_settings(f"examples/scenarios/suite/{name}.toml").for_world("mujoco")
        start = start_episode(settings, 3)
        parts = episode_parts(start, start.q_start)
        parts.world.close()
        fruit = start.settings.fruit
        bias = noise.radius_bias_px[0] + (noise.partial_colour_view[0] if partial else 0.0)
        assert start.noise.radius_bias_px[0] == pytest.approx(bias, abs=1e-12)  # the views' own
        own = noise.centre_offset_cov(fruit.radius_m, fruit.shape_index, seen)
        extra = partial_colour_cov(noise, fruit.radius_m) if partial else np.zeros((3, 3))
        np.testing.assert_allclose(parts.claims.offset_of(seen), own + extra, rtol=1e-12, atol=0.0)


def test_the_planner_expects_of_a_turning_detectors_views_what_the_filter_fuses_them_with():
    """The BVE's variance of a view not taken is the detector's: for a turning detector the
    model with its views' scales (the filter's, ``start_episode``), not the red fruit's."""
    from bve_mj.planning.size_information import size_information

    turning = load_settings("examples/scenarios/suite/turning.toml")
    red = dataclasses.replace(turning, detector=dataclasses.replace(turning.detector, ripe_class=None))
    _, k_c, k_r = load_noise_model("default").partial_colour_view
    assert k_c > 1.5 and k_r > 1.5  # the shipped terms: the test means something
    mine, theirs = size_information(turning), size_information(red)
    assert mine.bearing_var == pytest.approx(tuple(k_c * v for v in theirs.bearing_var), rel=1e-9, abs=1e-15)
    assert mine.size_var == pytest.approx(tuple(k_r * v for v in theirs.size_var), rel=1e-9, abs=1e-15)
