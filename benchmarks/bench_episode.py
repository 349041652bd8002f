"""Closed-loop MuJoCo episodes: time per view by stage, covariance honesty, and the final
error over seeded scenes for the BVE and the baselines, camera and range-only.

    python benchmarks/bench_episode.py [--scenes 50] [--workers 2]

Targets: a 15-view episode without video in under 5 s on this machine (issue 5), under 2 s
(the greenhouse issue, scene build and ready pose included). ``--scenes 0``: the timing only.
"""

from __future__ import annotations

import multiprocessing
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from bve_mj import Settings
from bve_mj.cli.script import ScriptParser, guarded, integer
from bve_mj.config import with_overrides
from bve_mj.loop.mujoco import run_mujoco_episode

ROWS = (("bve", "camera"), ("random", "camera"), ("circle", "camera"),
        ("bve", "range"), ("random", "range"), ("circle", "range"))  # fmt: skip


def _one(args: tuple[str, str, int]) -> tuple[str, str, int, float, float, int, str]:
    planner, measurement, seed = args
    s = with_overrides(Settings(), measurement={"kind": measurement}, planner={"kind": planner})
    ep = run_mujoco_episode(s, seed)
    nees = ep.result.final.mahalanobis_sq(ep.truth)
    return planner, measurement, seed, ep.final_error_mm, nees, len(ep.result.views), ep.result.outcome


def main() -> None:
    ap = ScriptParser()
    ap.add_argument("--scenes", type=integer(0), default=50)
    ap.add_argument("--workers", type=integer(1, 1024), default=2)
    args = ap.parse_args()

    # 1. a full 15-view episode (stopping rules off), time per stage
    s = with_overrides(
        Settings(),
        measurement={"kind": "camera"},
        episode={"views": 15, "stop_sigma_m": 1e-9, "stop_stable_m": 0.0, "stall_m": 0.0},
    )
    walls, starts, views = [], [], []
    stages: dict[str, list[float]] = {k: [] for k in ("plan_s", "ik_s", "control_s", "render_s", "detect_s")}
    for seed in range(5):
        t0 = time.perf_counter()
        ep = run_mujoco_episode(s, seed)
        walls.append(time.perf_counter() - t0)
        starts.append(walls[-1] - ep.result.wall_s)  # scene build, compile, ready pose
        views.append(len(ep.result.views))
        for v in ep.to_json()["views"][1:]:
            stages["plan_s"].append(v["plan_s"])
            for k in ("ik_s", "control_s", "render_s", "detect_s"):
                stages[k].append(v["timings_s"][k])
    per_view = ", ".join(f"{k[:-2]} {1e3 * np.median(x):.1f}" for k, x in stages.items())
    print(f"15-view episode without video (camera, BVE, 5 seeds, {min(views)}-{max(views)} views): "
          f"wall {np.median(walls):.2f} s median (max {max(walls):.2f} s; of it, scene build, compile "
          f"and ready pose {np.median(starts):.2f} s)")  # fmt: skip
    print(f"median per view [ms]: {per_view}")
    if args.scenes == 0:
        return

    # 2. final error and honesty over seeded scenes
    tasks = [(p, m, seed) for p, m in ROWS for seed in range(args.scenes)]
    t0 = time.perf_counter()
    # spawn, not fork: this process already holds EGL contexts, which forked children
    # inherit in a state that deadlocks their own rendering
    with ProcessPoolExecutor(
        max_workers=args.workers, mp_context=multiprocessing.get_context("spawn")
    ) as pool:
        results = list(pool.map(_one, tasks, chunksize=5))
    print(f"\n{args.scenes} seeded scenes per row, default episode (E5 + band, stopping rules on), "
          f"{time.perf_counter() - t0:.0f} s on {args.workers} workers")  # fmt: skip
    print(f"{'planner':<8} {'measurement':<11} {'median mm':>9} {'p95 mm':>8} {'mean mm':>8} "
          f"{'in 3σ %':>7} {'NEES':>6} {'views':>6} outcomes")  # fmt: skip
    for p, m in ROWS:
        rows = [r for r in results if r[0] == p and r[1] == m]
        err = np.array([r[3] for r in rows])
        nees = np.array([r[4] for r in rows])
        outcomes: dict[str, int] = {}
        for r in rows:
            outcomes[r[6]] = outcomes.get(r[6], 0) + 1
        print(
            f"{p:<8} {m:<11} {np.median(err):9.2f} {np.percentile(err, 95):8.2f} {np.mean(err):8.2f} "
            f"{100 * np.mean(nees <= 9.0):7.0f} {np.mean(nees):6.2f} {np.mean([r[5] for r in rows]):6.1f} "
            f"{outcomes}",
            flush=True,
        )


if __name__ == "__main__":
    guarded(main)
