"""Settings by part: each world's preset written once, moved keys still read (with a warning),
every allowed-value list defined once."""

import dataclasses
import warnings

import pytest

from bve_mj.cli import main
from bve_mj.config import (
    MOVED_KEYS,
    PRESETS,
    SECTIONS,
    EpisodeConfig,
    FruitPrior,
    RobotConfig,
    Settings,
    describe,
    load_settings,
    settings_from_dict,
    with_overrides,
)
from bve_mj.errors import ConfigError, SettingMovedWarning
from bve_mj.loop.mujoco import episode_settings

# --------------------------------------------------------------------------- presets


def test_the_greenhouse_preset_is_what_the_closed_loop_used_before():
    """The numbers EpisodeConfig carried and episode_settings copied over the sections."""
    g = Settings.greenhouse()
    assert g.constraints.band_distance_m == 0.30
    assert g.constraints.band_tolerance_m == 0.08
    assert g.constraints.step_m == 0.10
    assert g.filter.gate_probability == 0.99999
    assert g.measurement.reference_range_m == 0.30  # Σc at the band distance
    assert (g.measurement.kind, g.filter.state) == ("camera", "centre_radius")
    assert g.fruit == FruitPrior.for_scene(g.scene)  # the scene's fruit type
    assert g.planner.upright_weight == 0.1  # eye-in-hand images turned upright where the arm allows
    assert episode_settings(Settings()) == g  # the closed loop runs exactly the preset
    assert Settings().for_world("mujoco") == g


def test_a_lean_sigma_set_alone_keeps_the_scene_s_fruit_type():
    """``[fruit] tilt_sigma_deg`` alone changes the detector's lean prior, not the fruit type's
    size and shape prior; any size or shape set replaces the type's prior, as before."""
    from bve_mj.config import SceneConfig

    scene = SceneConfig(fruit_type="beefsteak")
    upright = Settings(scene=scene, fruit=FruitPrior(tilt_sigma_deg=0.0)).for_world("mujoco")
    assert upright.fruit == dataclasses.replace(FruitPrior.for_scene(scene), tilt_sigma_deg=0.0)
    sized = Settings(scene=scene, fruit=FruitPrior(radius_m=0.05, tilt_sigma_deg=0.0)).for_world("mujoco")
    assert sized.fruit == FruitPrior(radius_m=0.05, tilt_sigma_deg=0.0)


def test_the_paper_preset_is_the_synthetic_protocol():
    p = Settings.paper()
    assert (p.constraints.band_distance_m, p.constraints.band_tolerance_m, p.constraints.step_m) == (
        1.0,
        0.1,
        0.2,
    )
    assert p.filter.gate_probability is None  # off
    assert p.measurement.reference_range_m == 1.0
    assert (p.measurement.kind, p.filter.state) == ("range", "centre")
    assert p.planner.upright_weight == 0.0  # E5/E10 plan as the paper does, roll free
    assert p == Settings().for_world("synthetic")
    # settings no world resolved read as the paper's (as measurement.kind = "auto" does)
    s = Settings()
    assert (s.band_distance_m, s.band_tolerance_m, s.step_m, s.reference_range_m) == (1.0, 0.1, 0.2, 1.0)
    assert (s.sigma_c_m2() == p.sigma_c_m2()).all()
    assert s.planner.upright_weight is None and s.planner.upright == 0.0


def test_approach_mode_adapts_the_greenhouse_preset_as_before():
    s = episode_settings(with_overrides(Settings(), episode={"approach": True}))
    assert s.constraints.wall_distance_m == 0.04
    assert (s.planner.approach_aggressiveness, s.planner.approach_set_point) == (1.0, 4.0)
    assert (s.constraints.band_distance_m, s.constraints.step_m, s.filter.gate_probability) == (
        0.30,
        0.10,
        0.99999,
    )


def test_presets_are_written_once_and_resolving_twice_changes_nothing():
    assert set(PRESETS) == {"synthetic", "mujoco"}
    for world in PRESETS:
        once = Settings().for_world(world)  # type: ignore[arg-type]
        assert once.for_world(world) == once  # type: ignore[arg-type]
    # world-dependent fields are unset by default: the preset is their only value
    d = Settings()
    assert d.constraints.band_distance_m is None and d.constraints.step_m is None
    assert d.measurement.reference_range_m is None and d.filter.gate_probability is None


def test_a_value_set_holds_in_both_worlds():
    s = settings_from_dict(
        {
            "constraints": {"step_m": 0.15, "band_distance_m": 0.35},
            "filter": {"gate_probability": 0.999},
            "planner": {"upright_weight": 0.0},
        }
    )
    for world in ("synthetic", "mujoco"):
        r = s.for_world(world)
        assert (r.constraints.step_m, r.constraints.band_distance_m) == (0.15, 0.35)
        assert r.filter.gate_probability == 0.999
        assert r.planner.upright_weight == 0.0
    assert s.for_world("mujoco").measurement.reference_range_m == 0.35  # follows the band
    assert s.for_world("synthetic").measurement.reference_range_m == 1.0  # the protocol's
    fixed = settings_from_dict({"measurement": {"reference_range_m": 0.5}})
    assert fixed.for_world("mujoco").measurement.reference_range_m == 0.5


def test_a_band_tolerance_too_wide_for_the_world_names_the_field():
    s = settings_from_dict({"constraints": {"band_tolerance_m": 0.5}})
    assert s.for_world("synthetic").constraints.band_tolerance_m == 0.5  # < 1.0 m
    with pytest.raises(ConfigError) as info:
        s.for_world("mujoco")  # >= 0.30 m
    assert info.value.field == "constraints.band_tolerance_m"


def test_describe_lists_every_setting_with_the_preset_values():
    lines = describe(Settings.greenhouse())
    names = [line.split(" = ")[0] for line in lines[:-1]]
    expected = [f"{s}.{f.name}" for s, cls in SECTIONS.items() for f in dataclasses.fields(cls)]
    assert names == expected
    assert "constraints.band_distance_m = 0.3 [m]" in "\n".join(lines)
    assert "mm at 0.3 m" in lines[-1]
    assert not any(
        n.startswith("episode.") and n.split(".")[1] in ("step_m", "band_distance_m") for n in names
    )


# --------------------------------------------------------------------------- moved keys

MOVED = [(old, new, v) for (old, new), v in zip(MOVED_KEYS.items(), (0.33, 0.07, 0.12, 0.9999), strict=True)]


@pytest.mark.parametrize(("old", "new", "value"), MOVED)
def test_a_moved_key_is_read_under_its_new_name_with_a_warning(old, new, value, tmp_path):
    old_section, old_key = old.split(".")
    new_section, new_key = new.split(".")
    with pytest.warns(DeprecationWarning, match=rf"^{old} is deprecated: set {new}"):
        s = settings_from_dict({old_section: {old_key: value}})
    assert getattr(getattr(s, new_section), new_key) == value
    path = tmp_path / "old.toml"
    path.write_text(f"[{old_section}]\n{old_key} = {value}\n")
    with pytest.warns(SettingMovedWarning, match=rf"set {new}"):
        assert load_settings(path) == s
    with pytest.warns(DeprecationWarning, match=rf"set {new}"):
        assert with_overrides(Settings(), **{old_section: {old_key: value}}) == s
    with pytest.warns(DeprecationWarning):  # the same value under both names: no conflict
        assert settings_from_dict({old_section: {old_key: value}, new_section: {new_key: value}}) == s


def test_old_episode_keys_give_the_closed_loop_they_gave_before():
    with pytest.warns(DeprecationWarning):
        s = settings_from_dict(
            {
                "episode": {
                    "band_distance_m": 0.33,
                    "band_tolerance_m": 0.07,
                    "step_m": 0.12,
                    "gate_probability": 0.9999,
                }
            }
        )
    r = episode_settings(s)
    assert (r.constraints.band_distance_m, r.constraints.band_tolerance_m, r.constraints.step_m) == (
        0.33,
        0.07,
        0.12,
    )
    assert r.filter.gate_probability == 0.9999
    assert r.measurement.reference_range_m == 0.33
    with pytest.raises(TypeError):  # the section no longer has them
        EpisodeConfig(step_m=0.1)  # type: ignore[call-arg]


@pytest.mark.parametrize(("old", "new", "value"), MOVED)
def test_old_and_new_key_with_different_values_is_an_error_naming_both(old, new, value):
    old_section, old_key = old.split(".")
    new_section, new_key = new.split(".")
    data = {old_section: {old_key: value}, new_section: {new_key: value / 2}}
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # refused, not warned about
        with pytest.raises(ConfigError) as info:
            settings_from_dict(data)
    assert old in info.value.field and new in info.value.field
    assert old in str(info.value) and new in str(info.value) and "\n" not in str(info.value)


def test_a_bad_value_under_an_old_name_names_both_and_does_not_warn():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ConfigError) as info:
            settings_from_dict({"episode": {"step_m": -0.1}})
    assert info.value.field == "episode.step_m (now constraints.step_m)"


# --------------------------------------------------------------------------- through the CLI


def _paper(path):
    return main(
        ["paper", "--config", str(path), "--runs", "1", "--experiments", "E1", "--steps", "2", "--quiet"]
    )


def test_cli_reads_an_old_key_and_says_so_in_one_line(tmp_path, capsys):
    path = tmp_path / "old.toml"
    path.write_text("[episode]\ngate_probability = 0.999\n")
    assert _paper(path) == 0
    captured = capsys.readouterr()
    assert captured.err.strip() == (
        "bve-mj: warning: episode.gate_probability is deprecated: set filter.gate_probability "
        "(which both worlds use)"
    )
    assert "filter.gate_probability = 0.999" in captured.out  # describe() shows where it went


@pytest.mark.parametrize(
    ("text", "field"),
    [
        ("[constraints]\nstep_m = -0.1\n", "constraints.step_m"),
        ("[constraints]\nband_distance_m = 'far'\n", "constraints.band_distance_m"),
        ("[measurement]\nreference_range_m = 0.0\n", "measurement.reference_range_m"),
        ("[episode]\nstep_m = -0.1\n", "episode.step_m (now constraints.step_m)"),
        ("[episode]\nstep_m = 0.1\n[constraints]\nstep_m = 0.2\n", "episode.step_m and constraints.step_m"),
        ("[episode]\nprior = 'sphere'\n", "episode.prior"),
        ("[robot]\njoint_limits = 'loose'\n", "robot.joint_limits"),
    ],
)
def test_cli_bad_value_exits_2_with_one_line_naming_the_field(tmp_path, capsys, text, field):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    assert _paper(path) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"error: {field}" in err, err


def test_cli_episode_refuses_a_band_too_narrow_for_the_greenhouse(tmp_path, capsys):
    """Valid alone, invalid once the MuJoCo preset fills the band distance: exit 2 before the
    scene is built, one line naming the field."""
    path = tmp_path / "wide.toml"
    path.write_text("[constraints]\nband_tolerance_m = 0.5\n")
    assert main(["episode", "--config", str(path), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "error: constraints.band_tolerance_m" in err, err


# --------------------------------------------------------------------------- allowed values


def test_choices_are_named_from_their_one_list():
    with pytest.raises(ConfigError, match=r"one of detection, cube"):
        EpisodeConfig(prior="sphere")  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match=r"one of auto, urdf, emanual"):
        RobotConfig(joint_limits="loose")  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match=r"one of E1, E2, .*E10"):
        EpisodeConfig(experiment="E11")
