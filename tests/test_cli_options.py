"""Command-line options override a settings file only when given, for every option of every
command that maps to a setting; the Python API's default closed loop is the CLI's."""

from __future__ import annotations

import json

import numpy as np
import pytest

from bve_mj.cli import main
from bve_mj.cli.campaign import campaign_inputs
from bve_mj.cli.episode import episode_cli_settings
from bve_mj.cli.paper import paper_settings
from bve_mj.cli.parser import build_parser
from bve_mj.config import SensorConfig, Settings, load_settings

# (option, value on the command line, section.field it sets, its value there, a file value)
PAPER_OPTIONS = [
    ("--steps", "7", "protocol.steps", 7, 11),
    ("--measurement", "camera", "measurement.kind", "camera", "range"),
    ("--planner", "circle", "planner.kind", "circle", "random"),
    ("--planning-model", "paper", "planner.planning_model", "paper", "consistent"),
    ("--optimiser", "slsqp", "planner.optimiser", "slsqp", "trust-constr"),
    ("--robot", "panda", "robot.name", "panda", "ur5"),
    ("--joint-limits", "emanual", "robot.joint_limits", "emanual", "urdf"),
    ("--formulation", "joint", "robot.formulation", "joint", "cartesian"),
]
EPISODE_OPTIONS = [
    ("--experiment", "E1", "episode.experiment", "E1", "E10"),
    ("--views", "4", "episode.views", 4, 9),
    ("--measurement", "camera", "measurement.kind", "camera", "range"),
    ("--planner", "random", "planner.kind", "random", "circle"),
    ("--planning-model", "paper", "planner.planning_model", "paper", "consistent"),
    ("--robot", "ur5", "robot.name", "ur5", "panda"),
    ("--initial-error", "0.02", "episode.initial_error_m", 0.02, 0.07),
]
CAMPAIGN_OPTIONS = [
    ("--steps", "5", "protocol.steps", 5, 13),
    ("--views", "6", "episode.views", 6, 8),
]


def _get(settings: Settings, dotted: str) -> object:
    section, name = dotted.split(".")
    return getattr(getattr(settings, section), name)


def _file(tmp_path, dotted: str, value: object) -> str:
    section, name = dotted.split(".")
    path = tmp_path / "settings.toml"
    path.write_text(f"[{section}]\n{name} = {json.dumps(value)}\n")
    return str(path)


def _non_default(dotted: str, value: object) -> None:
    """The file's value must not be the default, or the test could not tell it survived."""
    default = _get(Settings(), dotted)
    assert value != default, f"{dotted}: pick a non-default value, not {default!r}"


@pytest.mark.parametrize(("option", "text", "dotted", "value", "in_file"), PAPER_OPTIONS)
def test_paper_option_overrides_the_file_only_when_given(tmp_path, option, text, dotted, value, in_file):
    _non_default(dotted, in_file)
    assert value != in_file
    config = _file(tmp_path, dotted, in_file)
    parser = build_parser()
    kept = paper_settings(parser.parse_args(["paper", "--config", config]))
    assert _get(kept, dotted) == in_file
    won = paper_settings(parser.parse_args(["paper", "--config", config, option, text]))
    assert _get(won, dotted) == value


@pytest.mark.parametrize(("option", "text", "dotted", "value", "in_file"), EPISODE_OPTIONS)
def test_episode_option_overrides_the_file_only_when_given(tmp_path, option, text, dotted, value, in_file):
    _non_default(dotted, in_file)
    assert value != in_file
    config = _file(tmp_path, dotted, in_file)
    parser = build_parser()
    assert _get(episode_cli_settings(parser.parse_args(["episode", "--config", config])), dotted) == in_file
    won = episode_cli_settings(parser.parse_args(["episode", "--config", config, option, text]))
    assert _get(won, dotted) == value


def test_episode_flags_keep_the_file_and_win_when_given(tmp_path):
    parser = build_parser()
    approach = _file(tmp_path, "episode.approach", True)
    assert episode_cli_settings(parser.parse_args(["episode", "--config", approach])).episode.approach
    plain = episode_cli_settings(parser.parse_args(["episode"]))
    assert not plain.episode.approach
    assert episode_cli_settings(parser.parse_args(["episode", "--approach"])).episode.approach
    noise = _file(tmp_path, "sensor.image_noise_std", 5.0)
    assert episode_cli_settings(parser.parse_args(["episode", "--config", noise])).sensor.image_noise_std == 5
    realistic = episode_cli_settings(parser.parse_args(["episode", "--config", noise, "--realistic"]))
    assert realistic.sensor == SensorConfig.realistic()


@pytest.mark.parametrize(("option", "text", "dotted", "value", "in_file"), CAMPAIGN_OPTIONS)
def test_campaign_option_overrides_the_file_only_when_given(tmp_path, option, text, dotted, value, in_file):
    _non_default(dotted, in_file)
    config = _file(tmp_path, dotted, in_file)
    parser = build_parser()
    base = ["campaign", "--out", str(tmp_path / "c"), "--config", config]
    assert _get(campaign_inputs(parser.parse_args(base))[0], dotted) == in_file
    assert _get(campaign_inputs(parser.parse_args([*base, option, text]))[0], dotted) == value


def test_campaign_axes_follow_the_file_unless_given(tmp_path):
    """--measurements, --initial-errors and --approach default to each world's settings."""
    parser = build_parser()
    out = ["--out", str(tmp_path / "c"), "--experiments", "E1"]
    settings, spec = campaign_inputs(parser.parse_args(["campaign", *out, "--worlds", "synthetic,mujoco"]))
    cells = spec.cells(settings)
    assert [(c.world, c.measurement) for c in cells] == [("synthetic", "range"), ("mujoco", "camera")]
    assert [c.initial_error_m for c in cells] == [0.15, 0.05]
    config = tmp_path / "s.toml"
    config.write_text(
        '[measurement]\nkind = "camera"\n[protocol]\ninitial_error_m = 0.3\n'
        "[episode]\ninitial_error_m = 0.02\napproach = true\n"
    )
    args = ["campaign", *out, "--worlds", "synthetic,mujoco", "--config", str(config)]
    cells = campaign_inputs(parser.parse_args(args))[1].cells(load_settings(config))
    assert [(c.world, c.measurement, c.initial_error_m, c.approach) for c in cells] == [
        ("synthetic", "camera", 0.3, True),
        ("mujoco", "camera", 0.02, True),
    ]
    args += ["--measurements", "range", "--initial-errors", "0.1"]
    cells = campaign_inputs(parser.parse_args(args))[1].cells(load_settings(config))
    assert {(c.measurement, c.initial_error_m) for c in cells} == {("range", 0.1)}


def test_a_scenario_can_name_another_arm(tmp_path):
    """joint_limits follows the arm unless set: a scenario naming panda gets panda's limits."""
    config = tmp_path / "panda.toml"
    config.write_text('[robot]\nname = "panda"\n')
    settings = episode_cli_settings(build_parser().parse_args(["episode", "--config", str(config)]))
    assert settings.robot.name == "panda" and settings.robot.limit_set == "urdf"
    assert Settings().robot.limit_set == "emanual"


def test_episode_config_measurement_reaches_the_run(tmp_path, capsys):
    """The file's [measurement] kind is what runs, what the header prints and what the JSON says."""
    config = tmp_path / "range.toml"
    config.write_text('[measurement]\nkind = "range"\n[episode]\nviews = 1\n')
    out = tmp_path / "ep.json"
    code = main(["episode", "--config", str(config), "--json", str(out), "--quiet"])
    assert code == 0
    assert "measurement=range" in capsys.readouterr().out
    assert json.loads(out.read_text())["settings"]["measurement"]["kind"] == "range"


def test_api_default_episode_is_the_cli_episode(tmp_path):
    from threadpoolctl import threadpool_limits

    from bve_mj.loop.mujoco import run_mujoco_episode

    out = tmp_path / "ep.json"
    assert main(["episode", "--seed", "3", "--json", str(out), "--quiet"]) in (0, 3)
    doc = json.loads(out.read_text())
    with threadpool_limits(limits=1, user_api="blas"):
        api = run_mujoco_episode(Settings(), 3)
    assert api.settings.measurement.kind == doc["settings"]["measurement"]["kind"] == "camera"
    assert api.result.outcome == doc["outcome"]
    assert len(api.result.views) == len(doc["views"])
    np.testing.assert_allclose(api.result.final.centre_m, doc["views"][-1]["estimate_m"], atol=1e-12)


def test_version(capsys):
    with pytest.raises(SystemExit) as info:
        build_parser().parse_args(["--version"])
    assert info.value.code == 0
    assert capsys.readouterr().out.startswith("bve-mj ")


def test_the_synthetic_world_refuses_the_radius_state_by_name(tmp_path, capsys):
    """The synthetic world measures the centre, not an image: a radius state there is a
    settings error naming filter.state (it was an IndexError deep in the loop)."""
    cfg = tmp_path / "cr.toml"
    cfg.write_text('[filter]\nstate = "centre_radius"\n')
    assert main(["paper", "--config", str(cfg), "--experiments", "E1", "--runs", "1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "filter.state" in err


def test_progress_is_a_tqdm_bar_on_stderr_and_silent_when_disabled(capsys):
    from bve_mj.cli.args import progress_printer

    report = progress_printer(True)
    for done in range(4):
        report(done, 3)
    err = capsys.readouterr().err
    assert "3/3" in err and "run" in err and "100%" in err
    quiet = progress_printer(False)
    quiet(1, 3)
    assert capsys.readouterr().err == ""
