import json
import math
import subprocess
import sys

import numpy as np
import pytest

from bve_mj.cli import main
from bve_mj.config import (
    CameraConfig,
    FruitPrior,
    MeasurementConfig,
    PlannerConfig,
    Settings,
    describe,
    load_settings,
    settings_from_dict,
)
from bve_mj.config.experiments import parse_experiments
from bve_mj.errors import BveError, ConfigError


@pytest.mark.parametrize(
    ("make", "field"),
    [
        (lambda: FruitPrior(radius_m=-0.03), "fruit.radius_m"),
        (lambda: CameraConfig(hfov_rad=0.0), "camera.hfov_rad"),
        (lambda: CameraConfig(hfov_rad=math.pi), "camera.hfov_rad"),
        (lambda: CameraConfig(hfov_rad="wide"), "camera.hfov_rad"),
        (lambda: CameraConfig(width_px=True), "camera.width_px"),
        (lambda: MeasurementConfig(sigma_c_m2=[[1, 0, 0], [0, -1, 0], [0, 0, 1]]), "measurement.sigma_c_m2"),
        (lambda: MeasurementConfig(sigma_c_m2=[[1, 2, 0], [0, 1, 0], [0, 0, 1]]), "measurement.sigma_c_m2"),
        (lambda: MeasurementConfig(kind="lidar"), "measurement.kind"),
        (lambda: PlannerConfig(optimiser="adam"), "planner.optimiser"),
        (lambda: parse_experiments("E1,E11"), "experiments"),
    ],
)
def test_bad_settings_raise_a_named_bve_error(make, field):
    with pytest.raises(ConfigError) as info:
        make()
    assert isinstance(info.value, BveError)
    assert info.value.field == field
    assert field in str(info.value) and "allowed" in str(info.value)


def test_sigma_c_is_derived_from_the_camera():
    s = Settings()
    f = 320 / math.tan(math.radians(34.5))
    assert s.camera.focal_px == pytest.approx(f)
    Sc = s.sigma_c_m2()
    assert math.sqrt(Sc[1, 1]) == pytest.approx(1.0 / f)  # 1 px at 1 m
    r_px = f * math.tan(math.asin(0.035))
    rel = math.hypot(0.15 / math.sqrt(3), 0.5 / r_px)
    assert math.sqrt(Sc[0, 0]) == pytest.approx(rel)
    assert np.count_nonzero(Sc - np.diag(np.diag(Sc))) == 0
    assert any("derived Sigma_c" in line for line in describe(s))


def test_toml_round_trip_and_did_you_mean(tmp_path):
    good = tmp_path / "good.toml"
    good.write_text('[planner]\nkind = "circle"\n[protocol]\nsteps = 12\n')
    s = load_settings(good)
    assert s.planner.kind == "circle" and s.protocol.steps == 12
    assert s.measurement == Settings().measurement
    with pytest.raises(ConfigError, match="did you mean 'steps'"):
        settings_from_dict({"protocol": {"stpes": 3}})
    with pytest.raises(ConfigError, match="did you mean 'planner'"):
        settings_from_dict({"planer": {}})
    bad = tmp_path / "bad.toml"
    bad.write_text("[planner\n")
    with pytest.raises(ConfigError, match="valid TOML"):
        load_settings(bad)
    with pytest.raises(ConfigError, match="readable"):
        load_settings(tmp_path / "missing.toml")


@pytest.mark.parametrize(
    ("argv", "field"),
    [
        (["paper", "--runs", "0"], "runs"),
        (["paper", "--runs", "ten"], "runs"),
        (["paper", "--seed", "-1"], "seed"),
        (["paper", "--experiments", "E0"], "experiments"),
        (["paper", "--measurement", "sonar"], "measurement.kind"),
        (["paper", "--planner", "greedy"], "planner.kind"),
        (["paper", "--planning-model", "magic"], "planner.planning_model"),
        (["paper", "--json", "/no/such/dir/out.json"], "json"),
        (["paper", "--bogus"], "unrecognized"),
        (["paper", "--robot", "kuka"], "robot.name"),
        (["paper", "--robot", "ur5", "--joint-limits", "emanual"], "robot.joint_limits"),
        (["paper", "--formulation", "polar"], "robot.formulation"),
        (["paper", "--runs", "1000000000000"], "runs"),  # bounded: not a run that never ends
        (["paper", "--workers", "100000"], "workers"),
        (["scenarios", "--seeds", "1000001"], "seeds"),
        (["episode", "--views", "10001"], "views"),
        (["episode", "--seed", str(2**63)], "seed"),
        (["campaign", "--out", "out/never", "--runs", "99999999"], "runs"),
    ],
)
def test_cli_bad_input_exits_2_with_one_line(argv, field, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and field in err
    assert "Traceback" not in err


def test_cli_writes_json_and_keeps_old_file_on_bad_input(tmp_path, capsys):
    out = tmp_path / "table.json"
    assert main(["paper", "--experiments", "E1,E5", "--runs", "3", "--steps", "4", "--json", str(out)]) == 0
    doc = json.loads(out.read_text())
    assert doc["settings"]["seed"] == 0 and doc["settings"]["protocol"]["steps"] == 4
    e1 = doc["experiments"]["E1"]
    for key in (
        "mape_pct",
        "mae_mm",
        "rmse_mm",
        "mse_mm2",
        "euclid_mean_mm",
        "euclid_median_mm",
        "euclid_p95_mm",
        "plan_ms_median",
        "runs",
        "inside_3sigma_pct",
        "nees_mean",
    ):
        assert key in e1
    assert e1["runs"] == 3
    assert doc["experiments"]["E5"]["runs"] == 3 and "runs_never_feasible" in doc["experiments"]["E5"]
    before = out.read_text()
    assert main(["paper", "--runs", "-3", "--json", str(out)]) == 2
    assert out.read_text() == before
    assert "E1" in capsys.readouterr().out


def test_console_script_runs():
    res = subprocess.run(
        [sys.executable, "-m", "bve_mj.cli", "paper", "--experiments", "E9", "--runs", "x"],
        capture_output=True,
        text=True,
        check=False,
    )
    assert res.returncode == 2 and res.stderr.count("\n") == 1


def test_import_has_no_side_effects():
    code = "import os, bve_mj; print(os.environ.get('MUJOCO_GL'), os.environ.get('OMP_NUM_THREADS'))"
    res = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        check=True,
        env={"PATH": "/usr/bin:/bin"},
    )
    assert res.stdout.strip() == "None None"
