import dataclasses

import numpy as np
import pytest

from bve_mj.campaigns.paper import run_synthetic, run_table
from bve_mj.config import Settings, with_overrides
from bve_mj.config.experiments import EXPERIMENTS
from bve_mj.estimation.metrics import consistency_metrics, euclidean_metrics, paper_metrics


def test_metrics_on_a_hand_made_example():
    truth = np.array([[1.0, 2.0, -0.5], [0.5, -1.0, 0.25]])
    est = np.array([[1.1, 2.0, -0.5], [0.5, -1.0, 0.5]])
    # per-axis errors: 0.1, 0, 0, 0, 0, -0.25  -> 6 entries
    m = paper_metrics(truth, est)
    assert m["mae_mm"] == pytest.approx((100 + 250) / 6)
    assert m["mse_mm2"] == pytest.approx((100**2 + 250**2) / 6)
    assert m["rmse_mm"] == pytest.approx(np.sqrt((100**2 + 250**2) / 6))
    assert m["mape_pct"] == pytest.approx((0.1 / 1.0 + 0.25 / 0.25) / 6 * 100)
    e = euclidean_metrics(truth, est)
    assert e["euclid_mean_mm"] == pytest.approx(175.0)
    assert e["euclid_median_mm"] == pytest.approx(175.0)
    c = consistency_metrics(truth, est, np.array([np.eye(3) * 0.1**2, np.eye(3) * 0.05**2]))
    # NEES: (0.1/0.1)^2 = 1 and (0.25/0.05)^2 = 25 -> one of two inside 3σ
    assert c["nees_mean"] == pytest.approx(13.0)
    assert c["inside_3sigma_pct"] == pytest.approx(50.0)


def test_experiment_presets_follow_the_paper():
    assert [e.loss for e in EXPERIMENTS.values()] == ["dispersion"] * 5 + ["max_eigenvalue"] * 5
    assert EXPERIMENTS["E1"].constraints == ("band",)
    assert EXPERIMENTS["E2"].constraints == ("band", "workspace")
    assert EXPERIMENTS["E3"].constraints == ("workspace", "outside_fruit", "cone")
    assert EXPERIMENTS["E4"].constraints == ("workspace", "outside_fruit", "cone", "wall")
    for a, b in zip(list(EXPERIMENTS.values())[:5], list(EXPERIMENTS.values())[5:], strict=True):
        assert a.constraints == b.constraints and a.needs_arm == b.needs_arm
    assert EXPERIMENTS["E5"].needs_arm and EXPERIMENTS["E10"].needs_arm


def _small(settings, workers):
    exps = [EXPERIMENTS["E1"], EXPERIMENTS["E8"]]
    return {k: v.as_dict() for k, v in run_table(settings, exps, 6, 3, workers=workers).items()}


def test_same_seed_same_table_serial_or_parallel():
    s = with_overrides(Settings(), protocol={"steps": 6})
    one = _small(s, 1)
    again = _small(s, 1)
    two = _small(s, 2)
    for table in (again, two):
        for name in one:
            for key, value in one[name].items():
                if key != "plan_ms_median":
                    assert table[name][key] == value, (name, key)


def test_runs_are_paired_across_planners():
    base = with_overrides(Settings(), protocol={"steps": 3})
    a = run_synthetic(base, EXPERIMENTS["E1"], 5, 2)
    b = run_synthetic(with_overrides(base, planner={"kind": "circle"}), EXPERIMENTS["E2"], 5, 2)
    np.testing.assert_array_equal(a["truth_m"], b["truth_m"])


@pytest.mark.parametrize("measurement", ["range", "camera"])
def test_bve_localises_the_fruit(measurement):
    """Seeded synthetic episodes reach the accuracy the covariance promises."""
    s = with_overrides(
        Settings(), measurement={"kind": measurement}, planner={"planning_model": "consistent"}
    )
    res = run_table(s, [EXPERIMENTS["E1"]], 16, 0, workers=1)["E1"].metrics
    initial_mean_mm = 0.15 / 2 * np.sqrt(3) * 1e3 * 1.0  # ~ E‖U[-.15,.15]^3‖ ≈ 136 mm
    limit = 80.0 if measurement == "range" else 5.0
    assert res["euclid_mean_mm"] < limit < initial_mean_mm
    assert res["inside_3sigma_pct"] >= 75.0


def test_camera_measurement_beats_range_only():
    base = with_overrides(Settings(), protocol={"steps": 15})
    exps = [EXPERIMENTS["E2"]]
    rng_ = run_table(base, exps, 8, 1, workers=1)["E2"].metrics["euclid_mean_mm"]
    cam = run_table(with_overrides(base, measurement={"kind": "camera"}), exps, 8, 1, workers=1)
    assert cam["E2"].metrics["euclid_mean_mm"] < 0.2 * rng_


def test_views_prior_fuses_each_planned_view():
    s = Settings()  # paper model: Σo from the fused views (eq. 9)
    assert s.prior_source == "views"
    consistent = dataclasses.replace(s.planner, planning_model="consistent")
    assert dataclasses.replace(s, planner=consistent).prior_source == "filter"


def test_tasks_longest_first_each_run_once():
    """The pool's tasks: MuJoCo runs first, one run index a task with every cell of it (one
    scene, built once), then the synthetic runs with the arm (E5, E10: several times the
    others' time), then the rest, so that no worker idles long at the end; every run exactly
    once."""
    from bve_mj.campaigns.executors import chunks
    from bve_mj.campaigns.spec import CampaignSpec

    spec = CampaignSpec(worlds=("synthetic", "mujoco"), experiments=("E1", "E5", "E6", "E10"))
    items = [(cell, run) for cell in spec.cells(Settings()) for run in range(13)]
    tasks = chunks(items, 2)
    flat = [it for task in tasks for it in task]
    assert sorted(flat, key=str) == sorted(items, key=str) and len(flat) == len(items)
    kinds = [
        "mujoco" if task[0][0].world == "mujoco" else "arm" if EXPERIMENTS[task[0][0].experiment].needs_arm
        else "other"
        for task in tasks
    ]  # fmt: skip
    assert kinds == sorted(kinds, key=["mujoco", "arm", "other"].index)
    synthetic_tasks = [task for task in tasks if task[0][0].world != "mujoco"]
    assert all(
        len({(c.world, EXPERIMENTS[c.experiment].needs_arm) for c, _ in task}) == 1
        for task in synthetic_tasks
    )
    mujoco_cells = [c for c in spec.cells(Settings()) if c.world == "mujoco"]
    mujoco_tasks = [task for task in tasks if task[0][0].world == "mujoco"]
    assert len(mujoco_tasks) == 13
    assert all(len({run for _, run in task}) == 1 and len(task) == len(mujoco_cells) for task in mujoco_tasks)
