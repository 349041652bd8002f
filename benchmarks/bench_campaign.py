"""Campaign throughput: runs per second with 1 and 2 local workers, synthetic and MuJoCo.

    python benchmarks/bench_campaign.py [--synthetic-runs 20] [--mujoco-runs 20]
                                        [--cases synthetic,mujoco,paired]

Synthetic: E1-E10, BVE, range-only, 30 planned views a run. MuJoCo: E5, BVE, camera,
closed-loop episodes (up to 15 views, stopping rules on): every episode a scene of its own.
Paired: the MuJoCo campaign that compares planners (E5, camera; BVE, random, circle) on
the same ``--mujoco-runs`` seeds: the three episodes of a run share one scene, built,
compiled and given a render context once by the worker that runs them. Each configuration
runs into a fresh directory, so nothing is resumed; the figures include process start-up
(spawn) and the SQLite commits. Run-level results are checked identical across worker counts.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

from bve_mj import Settings
from bve_mj.campaigns.runner import run_campaign
from bve_mj.campaigns.spec import CampaignSpec
from bve_mj.cli.script import ScriptParser, guarded, integer


def _stable(rows: tuple[dict, ...]) -> list[dict]:
    return [{k: v for k, v in r.items() if k not in ("wall_s", "plan_ms_median", "plan_ms")} for r in rows]


def main() -> None:
    ap = ScriptParser()
    ap.add_argument(
        "--synthetic-runs", type=integer(1), default=20, help="runs per experiment (10 experiments)"
    )
    ap.add_argument("--mujoco-runs", type=integer(1), default=20, help="episodes (E5)")
    ap.add_argument("--cases", default="synthetic,mujoco,paired", help="comma-separated")
    args = ap.parse_args()
    mujoco = {
        "experiments": ("E5",),
        "worlds": ("mujoco",),
        "measurements": ("camera",),
        "runs": args.mujoco_runs,
    }
    cases = {
        "synthetic": CampaignSpec(runs=args.synthetic_runs),
        "mujoco": CampaignSpec(**mujoco),
        "paired": CampaignSpec(planners=("bve", "random", "circle"), **mujoco),
    }
    chosen = [c.strip() for c in args.cases.split(",") if c.strip()]
    unknown = [c for c in chosen if c not in cases]
    if unknown or not chosen:
        ap.error(f"--cases: {', '.join(unknown) or 'none given'}; allowed: {', '.join(cases)}")
    cases = {c: cases[c] for c in chosen}
    with tempfile.TemporaryDirectory() as tmp:
        for name, spec in cases.items():
            rows = {}
            for workers in (1, 2):
                t0 = time.perf_counter()
                result = run_campaign(Settings(), spec, Path(tmp) / f"{name}{workers}", workers=workers)
                wall = time.perf_counter() - t0
                rows[workers] = result.rows
                n = result.computed_runs
                label = f"{workers} worker{'s' if workers > 1 else ' '}"
                print(f"{name:<9} {label}: {n:4d} runs in {wall:6.1f} s "
                      f"= {n / wall:6.2f} runs/s ({1e3 * wall / n:.0f} ms a run)")  # fmt: skip
            same = _stable(rows[1]) == _stable(rows[2])
            print(f"{name:<9} results identical with 1 and 2 workers: {same}")


if __name__ == "__main__":
    guarded(main)
