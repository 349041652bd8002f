"""Campaigns: seeding independent of the executor, resume after a kill, atomic outputs,
Dask on a loopback LocalCluster, and the CLI's validation."""

from __future__ import annotations

import csv
import json
import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from bve_mj.campaigns.runner import run_campaign
from bve_mj.campaigns.spec import CampaignSpec, Cell, parse_grid
from bve_mj.campaigns.store import RunStore
from bve_mj.cli import main
from bve_mj.config import Settings, with_overrides
from bve_mj.errors import ConfigError
from bve_mj.reporting.campaign_report import summary_document, write_campaign_outputs

TIMING = {"wall_s", "plan_ms_median", "plan_ms"}
SMALL = Settings()
SMALL = with_overrides(SMALL, protocol={"steps": 8})


def _stable(rows: list[dict]) -> list[dict]:
    return [{k: v for k, v in r.items() if k not in TIMING} for r in rows]


SPEC = CampaignSpec(
    experiments=("E1", "E6"),
    planners=("bve", "circle"),
    measurements=("range", "camera"),
    initial_errors_m=(0.05, 0.2),
    runs=3,
    seed=7,
)


def test_parse_grid_and_spec_validation() -> None:
    assert len(parse_grid("0:0.5:0.01")) == 51
    assert parse_grid("0:0.5:0.01")[-1] == pytest.approx(0.5)
    assert parse_grid("0.1,0.2") == (0.1, 0.2)
    for bad in ("", "a", "0:1", "1:0:0.1", "0:1:0", "-0.1", "nan", "0:1e9:1e-9"):
        with pytest.raises(ConfigError, match="initial_errors"):
            parse_grid(bad)
    for kwargs, field in (
        ({"worlds": ("mars",)}, "worlds"),
        ({"experiments": ("E11",)}, "experiments"),
        ({"planners": ("greedy",)}, "planners"),
        ({"measurements": ("depth",)}, "measurements"),
        ({"runs": 0}, "runs"),
        ({"runs": True}, "runs"),
        ({"seed": -1}, "seed"),
        ({"initial_errors_m": (-0.1,)}, "initial_errors"),
        ({"recovered_mm": 0.0}, "recovered_mm"),
    ):
        with pytest.raises(ConfigError, match=field):
            CampaignSpec(**kwargs)  # type: ignore[arg-type]
    cells = SPEC.cells(Settings())
    assert len(cells) == 2 * 2 * 2 * 2
    assert len({c.key(r) for c in cells for r in range(SPEC.runs)}) == 16 * 3


def test_results_do_not_depend_on_workers_and_resume_extends(tmp_path: Path) -> None:
    serial = run_campaign(SMALL, SPEC, tmp_path / "serial", workers=1)
    parallel = run_campaign(SMALL, SPEC, tmp_path / "parallel", workers=2)
    assert serial.computed_runs == parallel.computed_runs == 48
    assert _stable(list(serial.rows)) == _stable(list(parallel.rows))
    # paired: run i has the same truth in every cell
    truths = {(r["run"], tuple(r["truth_m"])) for r in serial.rows}
    assert len(truths) == SPEC.runs
    # more runs in the same directory: the first three are reused, not recomputed
    bigger = CampaignSpec(**{**SPEC.as_dict(), "runs": 4})  # type: ignore[arg-type]
    resumed = run_campaign(SMALL, bigger, tmp_path / "serial", workers=1)
    assert (resumed.resumed_runs, resumed.computed_runs) == (48, 16)
    fresh = run_campaign(SMALL, bigger, tmp_path / "fresh", workers=1)
    assert _stable(list(resumed.rows)) == _stable(list(fresh.rows))


def test_outputs_are_whole_and_strict_json(tmp_path: Path) -> None:
    result = run_campaign(SMALL, SPEC, tmp_path, workers=1)
    paths = write_campaign_outputs(result, plots=True)
    names = {p.name for p in paths}
    assert {
        "runs.csv",
        "summary.json",
        "error_by_view.png",
        "recoverability.png",
        "sample_paths.png",
    } <= names
    doc = json.loads((tmp_path / "summary.json").read_text(), parse_constant=lambda c: pytest.fail(c))
    assert doc["spec"]["seed"] == 7 and len(doc["cells"]) == 16 and len(doc["runs"]) == 48
    cell = doc["cells"][0]
    assert cell["runs"] == 3 and cell["euclid_mean_mm"] > 0 and len(cell["error_by_view_median_mm"]) == 9
    with open(tmp_path / "runs.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 48 and float(rows[0]["error_mm"]) > 0
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")], "temporary files left behind"
    # camera measurements localise far better than range-only ones (the whole point of the camera model)
    by = {c["label"]: c for c in doc["cells"]}
    assert (
        by["synthetic E1 bve camera e0=0.05 m"]["euclid_mean_mm"]
        < 0.2 * by["synthetic E1 bve range e0=0.05 m"]["euclid_mean_mm"]
    )


def test_store_refuses_other_settings_and_unreadable_files(tmp_path: Path) -> None:
    spec = CampaignSpec(experiments=("E1",), runs=1)
    run_campaign(SMALL, spec, tmp_path / "c", workers=1)
    other = with_overrides(SMALL, planner={"optimiser": "trust-constr"})
    with pytest.raises(ConfigError, match=r"out: .*planner\.optimiser"):
        run_campaign(other, spec, tmp_path / "c", workers=1)
    with pytest.raises(ConfigError, match="seed"):
        run_campaign(SMALL, CampaignSpec(experiments=("E1",), runs=1, seed=3), tmp_path / "c", workers=1)
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / RunStore.FILENAME).write_bytes(b"not a database at all" * 100)
    with pytest.raises(ConfigError, match="unreadable"):
        run_campaign(SMALL, spec, bad, workers=1)
    (tmp_path / "file").write_text("x")
    with pytest.raises(ConfigError, match="a directory"):
        run_campaign(SMALL, spec, tmp_path / "file", workers=1)


def test_the_store_records_the_code_and_a_resume_under_other_code_says_so(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from bve_mj.campaigns.store import code_identity

    code = code_identity()
    assert code["version"] and code["commit"]
    spec = CampaignSpec(experiments=("E1",), runs=1)
    first = run_campaign(SMALL, spec, tmp_path / "c", workers=1)
    assert first.code_change is None
    assert run_campaign(SMALL, spec, tmp_path / "c", workers=1).code_change is None  # same code
    db = sqlite3.connect(tmp_path / "c" / RunStore.FILENAME)
    with db:
        db.execute("UPDATE meta SET value = ? WHERE name = 'code'", (json.dumps({**code, "commit": "0ld"}),))
    db.close()
    again = run_campaign(SMALL, spec, tmp_path / "c", workers=1)
    assert again.code_change is not None and "0ld" in again.code_change
    assert again.rows == first.rows  # resumed, nothing lost
    with pytest.raises(ConfigError, match="strict"):
        run_campaign(SMALL, spec, tmp_path / "c", workers=1, strict=True)
    argv = ["campaign", "--out", str(tmp_path / "c"), "--experiments", "E1", "--runs", "1",
            "--worlds", "synthetic", "--planners", "bve", "--quiet", "--workers", "1"]  # fmt: skip
    config = tmp_path / "small.toml"
    config.write_text("[protocol]\nsteps = 8\n")
    capsys.readouterr()
    assert main([*argv, "--config", str(config), "--strict"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--strict" in err and "0ld" in err
    assert main([*argv, "--config", str(config)]) == 0
    assert "resumed under other code" in capsys.readouterr().err


def test_a_crashing_run_is_recorded_and_retried(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import bve_mj.campaigns.executors as campaign

    real = campaign.run_cell

    def flaky(settings: Settings, cell: Cell, seed: int, run: int) -> dict:
        if run == 1:
            raise RuntimeError("injected bug")
        return real(settings, cell, seed, run)

    spec = CampaignSpec(experiments=("E1",), runs=3)
    monkeypatch.setattr(campaign, "run_cell", flaky)
    first = run_campaign(SMALL, spec, tmp_path, workers=1)
    assert len(first.crashed) == 1 and "injected bug" in first.crashed[0]
    doc = summary_document(first)
    assert doc["cells"][0]["finished_runs"] == 2 and doc["cells"][0]["outcomes"]["crashed"] == 1
    monkeypatch.setattr(campaign, "run_cell", real)
    second = run_campaign(SMALL, spec, tmp_path, workers=1)
    assert (second.resumed_runs, second.computed_runs, second.crashed) == (2, 1, ())


def test_killed_campaign_resumes_without_losing_or_recomputing(tmp_path: Path) -> None:
    out = tmp_path / "killed"
    cmd = [sys.executable, "-m", "bve_mj.cli", "campaign", "--out", str(out), "--experiments", "E1",
           "--runs", "400", "--steps", "8", "--workers", "1", "--no-plots", "--quiet"]  # fmt: skip
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    db = out / RunStore.FILENAME
    stored = 0
    deadline = time.monotonic() + 60
    try:
        while time.monotonic() < deadline and proc.poll() is None:
            if db.exists():
                try:
                    with sqlite3.connect(db, timeout=5) as con:
                        stored = con.execute("SELECT COUNT(*) FROM runs").fetchone()[0]
                except sqlite3.OperationalError:
                    stored = 0
                if stored >= 20:
                    break
            time.sleep(0.02)
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
    assert 20 <= stored < 400, "the campaign was not killed half way"
    code = main(["campaign", "--out", str(out), "--experiments", "E1", "--runs", "30", "--steps", "8",
                 "--workers", "1", "--no-plots", "--quiet"])  # fmt: skip
    assert code == 0
    doc = json.loads((out / "summary.json").read_text())
    assert doc["resumed_runs"] >= 20 and doc["resumed_runs"] + doc["computed_runs"] == 30
    spec = CampaignSpec(experiments=("E1",), runs=30)
    fresh = run_campaign(SMALL, spec, tmp_path / "fresh", workers=1)
    killed_rows = [r for r in doc["runs"]]
    fresh_rows = [{k: v for k, v in r.items() if k not in ("error_by_view_mm", "camera_path_m",
                                                             "estimate_path_m", "cov_m2", "prior_m")}
                  for r in fresh.rows]  # fmt: skip
    assert _stable(killed_rows) == _stable(fresh_rows)


def test_dask_local_cluster_gives_the_local_results(tmp_path: Path) -> None:
    distributed = pytest.importorskip("distributed")
    spec = CampaignSpec(experiments=("E1", "E5"), planners=("bve",), measurements=("camera",), runs=3)
    local = run_campaign(SMALL, spec, tmp_path / "local", workers=1)
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, host="127.0.0.1", dashboard_address=None, processes=True
    ) as cluster:
        remote = run_campaign(SMALL, spec, tmp_path / "dask", scheduler=cluster.scheduler_address)
    assert remote.computed_runs == 6
    assert _stable(list(local.rows)) == _stable(list(remote.rows))


def test_dask_scheduler_errors_are_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("distributed")
    code = main(["campaign", "--out", str(tmp_path / "x"), "--experiments", "E1", "--runs", "1",
                 "--scheduler", "tcp://127.0.0.1:9", "--no-plots"])  # fmt: skip
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "scheduler" in err


@pytest.mark.parametrize(
    ("argv", "field"),
    [
        (["--worlds", "mars"], "worlds"),
        (["--planners", "bve,greedy"], "planners"),
        (["--runs", "0"], "runs"),
        (["--initial-errors", "0:x:1"], "initial_errors"),
        (["--recovered-mm", "-1"], "recovered-mm"),
        (["--experiments", "E0"], "experiments"),
        (["--workers", "0"], "workers"),
    ],
)
def test_campaign_cli_bad_input_exits_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], field: str
) -> None:
    code = main(["campaign", "--out", str(tmp_path / "c"), *argv])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and field in err, err
    assert not (tmp_path / "c").exists()


def test_recoverability_cli_and_mujoco_rows_reproduce_as_episodes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code = main(["recoverability", "--out", str(tmp_path / "r"), "--experiments", "E1",
                 "--initial-errors", "0,0.3", "--runs", "2", "--steps", "6", "--workers", "1"])  # fmt: skip
    assert code == 0
    assert (tmp_path / "r" / "recoverability.png").stat().st_size > 10_000
    out = capsys.readouterr().out
    assert "synthetic E1 bve range e0=0.3 m" in out
    # MuJoCo: one run; its row's episode seed replays it exactly
    from bve_mj.loop.mujoco import run_mujoco_episode

    spec = CampaignSpec(experiments=("E5",), worlds=("mujoco",), measurements=("camera",), runs=1, seed=4)
    settings = with_overrides(Settings(), episode={"views": 4})
    result = run_campaign(settings, spec, tmp_path / "m", workers=1)
    row = result.rows[0]
    assert row["outcome"] in ("converged", "stable", "max_views") and row["error_mm"] < 5.0
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):  # as bve-mj episode runs it
        replay = run_mujoco_episode(
            with_overrides(settings, measurement={"kind": "camera"}), row["episode_seed"]
        )
    assert replay.final_error_mm == pytest.approx(row["error_mm"], abs=1e-12)
    assert np.allclose(replay.truth, row["truth_m"])


def test_results_page_numbers_come_from_its_campaigns(tmp_path: Path) -> None:
    docs = tmp_path / "docs"
    docs.mkdir()
    argv = ["results", "--out", str(docs / "results.md"), "--work", str(tmp_path / "work"), "--runs", "2",
            "--mujoco-runs", "1", "--recover-runs", "1", "--recover-grid", "0,0.3", "--experiments", "E1",
            "--workers", "2", "--scenario-seeds", "1", "--quiet"]  # fmt: skip
    code = main(argv)
    assert code == 0
    page = (docs / "results.md").read_text()
    for heading in (
        "The paper's table beside ours",
        "Recoverability",
        "against the baselines",
        "Sample paths",
        "scenario suite",
    ):
        assert heading in page
    assert "| truss_chain |" in page and "### Measurement: range" in page
    for line in page.splitlines():
        if line.startswith("!["):
            target = line[line.index("(") + 1 : line.index(")")]
            assert (docs / target).stat().st_size > 5_000, target
    summary = json.loads((tmp_path / "work" / "synthetic" / "summary.json").read_text())
    e1 = next(c for c in summary["cells"] if c["label"] == "synthetic E1 bve range e0=0.15 m")
    row = next(line for line in page.splitlines() if line.startswith("| E1 | dispersion"))
    assert f"| {e1['euclid_mean_mm']:.1f} |" in row and "| 37.1 | 15.5 |" in row
    # the baselines' table holds every baseline the campaign ran, fixed views too
    fixed = next(c for c in summary["cells"] if c["label"] == "synthetic E1 fixed range e0=0.15 m")
    assert "| exp | BVE | random | circle | fixed | BVE best? |" in page
    against = next(
        line for line in page.splitlines() if line.startswith(f"| E1 | {e1['euclid_mean_mm']:.1f} |")
    )
    assert f"| {fixed['euclid_mean_mm']:.1f} | " in against
    # a second call resumes everything: nothing is recomputed
    assert main(argv) == 0
    assert "0 computed in this call" in (docs / "results.md").read_text()
