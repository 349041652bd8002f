"""Campaign throughput: runs per second with 1 and 2 local workers, synthetic and MuJoCo.

    python benchmarks/bench_campaign.py [--synthetic-runs 20] [--mujoco-runs 20]

Synthetic: E1-E10, BVE, range-only, 30 planned views a run. MuJoCo: E5, BVE, camera,
closed-loop episodes (up to 15 views, stopping rules on). Each configuration runs into a
fresh directory, so nothing is resumed; the figures include process start-up (spawn) and
the SQLite commits. Run-level results are checked identical across worker counts.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from bve_mj import Settings
from bve_mj.campaigns.runner import run_campaign
from bve_mj.campaigns.spec import CampaignSpec


def _stable(rows: tuple[dict, ...]) -> list[dict]:
    return [{k: v for k, v in r.items() if k not in ("wall_s", "plan_ms_median", "plan_ms")} for r in rows]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--synthetic-runs", type=int, default=20, help="runs per experiment (10 experiments)")
    ap.add_argument("--mujoco-runs", type=int, default=20, help="episodes (E5)")
    args = ap.parse_args()
    cases = {
        "synthetic": CampaignSpec(runs=args.synthetic_runs),
        "mujoco": CampaignSpec(
            experiments=("E5",), worlds=("mujoco",), measurements=("camera",), runs=args.mujoco_runs
        ),
    }
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
    main()
