"""Median BVE planning time per step, per loss × measurement × optimiser, on E1-E4 / E6-E9.

    python benchmarks/bench_planning.py [--runs 10]

Target (issue 2): at most 2 ms per step for E1-E4 with the default optimiser (SLSQP).
"""

from __future__ import annotations

from typing import get_args

from bve_mj.campaigns.paper import run_table
from bve_mj.cli.script import ScriptParser, guarded, integer, names
from bve_mj.config import Settings, with_overrides
from bve_mj.config.experiments import EXPERIMENTS
from bve_mj.config.fields import OptimiserName


def main() -> None:
    ap = ScriptParser()
    ap.add_argument("--runs", type=integer(1), default=10)
    ap.add_argument("--optimisers", type=names(get_args(OptimiserName)), default=["slsqp", "trust-constr"])
    args = ap.parse_args()
    print(f"median plan time per step [ms] and mean Euclidean error [mm], {args.runs} runs, seed 0, 1 worker")
    print(f"{'optimiser':<13} {'loss':<15} {'measurement':<11} {'model':<11} {'plan ms':>8} {'eucl mm':>8}")
    for optimiser in args.optimisers:
        for loss, experiments in (("dispersion", "E1,E2,E3,E4"), ("max_eigenvalue", "E6,E7,E8,E9")):
            for measurement in ("range", "camera"):
                for model in ("paper", "consistent"):
                    s = with_overrides(
                        Settings(),
                        measurement={"kind": measurement},
                        planner={"optimiser": optimiser, "planning_model": model},
                    )
                    exps = [EXPERIMENTS[n] for n in experiments.split(",")]
                    res = run_table(s, exps, args.runs, 0, workers=1)
                    plan = sorted(v.metrics["plan_ms_median"] for v in res.values())
                    err = sum(v.metrics["euclid_mean_mm"] for v in res.values()) / len(res)
                    print(
                        f"{optimiser:<13} {loss:<15} {measurement:<11} {model:<11} "
                        f"{plan[len(plan) // 2]:8.2f} {err:8.1f}",
                        flush=True,
                    )


if __name__ == "__main__":
    guarded(main)
