"""The BVE step with the arm's kinematic constraint (E5, E10): time and feasibility for
the joint-space and Cartesian formulations.

    python benchmarks/bench_kinematic.py [--runs 20] [--cartesian-runs 3]

Target (issue 3): median at most 10 ms per step. The Cartesian formulation (IK residual as
a constraint, finite-difference gradient) is slow; it runs on fewer runs.
"""

from __future__ import annotations

import time

import numpy as np

from bve_mj.campaigns.paper import run_synthetic
from bve_mj.cli.script import ScriptParser, guarded, integer
from bve_mj.config import Settings, with_overrides
from bve_mj.config.experiments import EXPERIMENTS


def main() -> None:
    ap = ScriptParser()
    ap.add_argument("--runs", type=integer(1), default=20)
    ap.add_argument("--cartesian-runs", type=integer(1), default=3)
    args = ap.parse_args()
    print("BVE step with kinematic feasibility (Manipulator-H, emanual limits, range measurement)")
    print(
        f"{'formulation':<11} {'exp':<4} {'runs':>4} {'median ms':>9} {'p95 ms':>8} "
        f"{'feasible steps %':>16} {'no-reach runs':>13} {'eucl mm':>8} {'wall s':>7}"
    )
    for formulation, runs in (("joint", args.runs), ("cartesian", args.cartesian_runs)):
        s = with_overrides(Settings(), robot={"formulation": formulation})
        for name in ("E5", "E10"):
            t0 = time.perf_counter()
            recs = [run_synthetic(s, EXPERIMENTS[name], 0, r) for r in range(runs)]
            plan_ms = np.concatenate([r["plan_ms"] for r in recs])
            steps = plan_ms.size
            feasible = steps - sum(r["restoring_steps"] for r in recs)
            never = sum(not r["ever_feasible"] for r in recs)
            err = np.mean([r["error_mm"] for r in recs])
            print(
                f"{formulation:<11} {name:<4} {runs:4d} {np.median(plan_ms):9.2f} "
                f"{np.percentile(plan_ms, 95):8.1f} {100 * feasible / steps:16.1f} {never:13d} "
                f"{err:8.1f} {time.perf_counter() - t0:7.1f}",
                flush=True,
            )


if __name__ == "__main__":
    guarded(main)
