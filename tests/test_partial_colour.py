"""The own offset of fruit a detector of a class short of red fits: the fit recovers it from
calibration rows, the claim adds it only for such a detector, and the episode wires it."""

import json
import pickle

import numpy as np
import pytest

from bve_mj.config import CameraConfig, DetectorConfig
from bve_mj.config.settings import load_settings
from bve_mj.errors import ConfigError
from bve_mj.estimation.noise import Outline, load_noise_model
from bve_mj.estimation.noise_fit import fit_noise_model
from bve_mj.estimation.partial_colour import fit_partial_colour_offset, partial_colour_cov
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


def test_a_model_file_without_the_term_loads_with_none_and_a_negative_one_is_refused(tmp_path):
    data = load_noise_model("default").to_json()
    path = tmp_path / "old.json"
    path.write_text(json.dumps({k: v for k, v in data.items() if k != "partial_colour_offset"}))
    assert load_noise_model(str(path)).partial_colour_offset == 0.0
    path.write_text(json.dumps({**data, "partial_colour_offset": -1e-5}))
    with pytest.raises(ConfigError, match="partial_colour_offset"):
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
        own = noise.centre_offset_cov(fruit.radius_m, fruit.shape_index, seen)
        extra = partial_colour_cov(noise, fruit.radius_m) if partial else np.zeros((3, 3))
        np.testing.assert_allclose(parts.claims.offset_of(seen), own + extra, rtol=1e-12, atol=0.0)
