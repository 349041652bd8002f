"""Mean Euclidean error per experiment for the BVE (both planning models) and the
baselines, in both measurement modes, same seeds and steps; plus honesty figures.

    python benchmarks/compare_planners.py [--runs 100] [--seed 0]
"""

from __future__ import annotations

from bve_mj.campaigns.paper import run_table
from bve_mj.cli.script import SEED, ScriptParser, guarded, integer
from bve_mj.config import Settings, with_overrides
from bve_mj.config.experiments import EXPERIMENTS

ROWS: tuple[tuple[str, dict[str, object]], ...] = (
    ("bve/consistent", {"kind": "bve", "planning_model": "consistent"}),
    ("bve/paper", {"kind": "bve", "planning_model": "paper"}),
    ("random", {"kind": "random"}),
    ("circle", {"kind": "circle"}),
)


def main() -> None:
    ap = ScriptParser()
    ap.add_argument("--runs", type=integer(1), default=100)
    ap.add_argument("--seed", type=SEED, default=0)
    ap.add_argument("--workers", type=integer(1, 1024), default=2)
    args = ap.parse_args()
    names = ("E1", "E2", "E3", "E4", "E6", "E7", "E8", "E9")
    exps = [EXPERIMENTS[n] for n in names]
    means: dict[tuple[str, str], dict[str, float]] = {}
    for measurement in ("range", "camera"):
        print(f"\nmeasurement={measurement}: mean Euclidean error [mm] ({args.runs} runs, seed {args.seed})")
        print(f"{'planner':<16}" + "".join(f"{n:>8}" for n in names))
        honesty = {}
        for label, planner in ROWS:
            s = with_overrides(Settings(), measurement={"kind": measurement}, planner=planner)
            res = run_table(s, exps, args.runs, args.seed, workers=args.workers)
            means[(measurement, label)] = {n: res[n].metrics["euclid_mean_mm"] for n in names}
            honesty[label] = {
                n: (res[n].metrics["inside_3sigma_pct"], res[n].metrics["nees_mean"]) for n in names
            }
            print(
                f"{label:<16}" + "".join(f"{means[(measurement, label)][n]:8.2f}" for n in names), flush=True
            )
        best = means[(measurement, "bve/consistent")]
        wins = [n for n in names if best[n] < min(means[(measurement, b)][n] for b in ("random", "circle"))]
        print(f"bve/consistent beats both baselines on {len(wins)}/{len(names)}: {','.join(wins)}")
        print("inside 3σ % / mean NEES per experiment:")
        for label, per in honesty.items():
            print(f"  {label:<14}" + "".join(f"{p:6.0f}/{q:4.1f}" for p, q in per.values()))
    print("\ncamera / range mean Euclidean error ratio (bve/consistent, bve/paper):")
    for label in ("bve/consistent", "bve/paper"):
        r, c = means[("range", label)], means[("camera", label)]
        print(f"  {label:<14}" + "".join(f"{n}:{c[n] / r[n]:.3f} " for n in names))


if __name__ == "__main__":
    guarded(main)
