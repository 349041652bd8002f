"""Every example and benchmark script turns bad input into one line naming the argument and
what is allowed, exit 2, before it runs or writes anything (``bve_mj.cli.script``)."""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

import pytest

from bve_mj.cli.script import SEED, folder, integer, integers, names, number

ROOT = Path(__file__).resolve().parents[1]

BAD = {
    # examples: positional arguments as their docstrings say
    "examples/approach_video.py": (["out", "one"], "seed"),
    "examples/box_detector.py": (["0", "no_such_scene"], "no_such_scene"),
    "examples/campaign.py": (["out/campaign_example", "0"], "runs"),
    "examples/gym_policies.py": (["0"], "episodes"),
    "examples/headless_episode.py": (["-1"], "seed"),
    "examples/paper_table.py": (["zero"], "runs"),
    "examples/pick_figure.py": (["9105", "README.md"], "out_dir"),
    "examples/plum_figure.py": (["README.md/x"], "out_dir"),
    "examples/render_scene.py": (["4.5"], "seed"),
    "examples/rims_figure.py": (["4", "README.md/x"], "out_dir"),
    "examples/sample_paths.py": (["pyproject.toml"], "out_dir"),
    "examples/unhide_figure.py": (["seed"], "seed"),
    # benchmarks
    "benchmarks/bench_arm_clearance.py": (["--episodes", "0"], "--episodes"),
    "benchmarks/bench_campaign.py": (["--mujoco-runs", "-2"], "--mujoco-runs"),
    "benchmarks/bench_coverage_oracle.py": (["--views", "0"], "--views"),
    "benchmarks/bench_detectors.py": (["--kinds", "builtin,yolo"], "--kinds"),
    "benchmarks/bench_episode.py": (["--workers", "0"], "--workers"),
    "benchmarks/bench_faults.py": (["--seed", "-1"], "--seed"),
    "benchmarks/bench_fruit_disputes.py": (["--only", "truss_chain,no_such_scene"], "no_such_scene"),
    "benchmarks/bench_fruit_planning.py": (["--episodes", "many"], "--episodes"),
    "benchmarks/bench_gym.py": (["--steps", "0"], "--steps"),
    "benchmarks/bench_harvest.py": (["--planner", "greedy"], "--planner"),
    "benchmarks/bench_ik.py": (["--targets", "10000000"], "--targets"),
    "benchmarks/bench_instances.py": (["--views", "0"], "--views"),
    "benchmarks/bench_kinematic.py": (["--runs", "0"], "--runs"),
    "benchmarks/bench_perception.py": (["--views", "-3"], "--views"),
    "benchmarks/bench_planning.py": (["--optimisers", "adam"], "--optimisers"),
    "benchmarks/bench_table.py": (["--runs", "0"], "--runs"),
    "benchmarks/bench_unmeasured.py": (["--only", "no_such_scene"], "no_such_scene"),
    "benchmarks/bench_upright.py": (["--episodes", "0"], "--episodes"),
    "benchmarks/bench_view_twins.py": (["--scenes", "0"], "--scenes"),
    "benchmarks/compare_horizon.py": (["--horizons", "1,9"], "--horizons"),
    "benchmarks/compare_planners.py": (["--seed", "x"], "--seed"),
    "benchmarks/claim_moments.py": (["no_such_file.json"], "rows_json"),
    "benchmarks/partial_colour_offset.py": (["no_such_file.json"], "rows_json"),
    "benchmarks/detection_by_arc.py": (["--only", "no_such_scene"], "--only"),
    "benchmarks/honesty_tails.py": (["no_such_file.json"], "suite_json"),
    "benchmarks/episode_claims.py": (["no_such_file.json", "--check", "README.md"], "calibration"),
}


def test_every_script_is_checked():
    found = [p for d in ("examples", "benchmarks") for p in (ROOT / d).glob("*.py")]
    assert sorted(str(p.relative_to(ROOT)) for p in found) == sorted(BAD)


@pytest.mark.parametrize("script", sorted(BAD))
def test_bad_input_is_one_line_and_exit_2(script, tmp_path):
    args, named = BAD[script]
    res = subprocess.run(
        [sys.executable, str(ROOT / script), *args],
        cwd=ROOT, capture_output=True, text=True, check=False, timeout=120,
    )  # fmt: skip
    lines = res.stderr.strip().splitlines()
    assert res.returncode == 2, res.stderr[-2000:]
    assert len(lines) == 1 and named in lines[0], lines
    assert "allowed:" in lines[0] or "(choose from" in lines[0], lines
    assert res.stdout == ""


def test_the_argument_types():
    assert integer(1, 5)("5") == 5 and SEED("0") == 0 and SEED(str(2**63 - 1)) == 2**63 - 1
    assert number(0.0, 1.0)("0.25") == 0.25
    assert integers(1, 6)("1,2,3") == [1, 2, 3] and names(["a", "b"])("b, a") == ["b", "a"]
    for parse, text in (
        (integer(1, 5), "6"), (integer(1, 5), "0"), (integer(1, 5), "2.0"), (SEED, "-1"),
        (number(0.0, 1.0), "nan"), (number(0.0, 1.0), "1.5"), (number(0.0), "inf"),
        (integers(1, 6), "1,,2"), (integers(1, 6), "7"), (names(["a"]), "a,c"), (names(["a"]), ""),
        (folder, "README.md"), (folder, "README.md/out"),
    ):  # fmt: skip
        with pytest.raises(argparse.ArgumentTypeError, match="allowed"):
            parse(text)
    assert folder("out/new/deeper") == "out/new/deeper"
