"""Greedy BVE against receding horizons (H views planned, the first executed) and the
baselines, on the paper's synthetic protocol, paired seeds: mean and median Euclidean error,
the final covariance's rms error sqrt(tr P) (with the camera measurement the filter is the
exact Kalman filter, so this is the expected error, without the noise of one draw), and the
planning time per step.

    python benchmarks/compare_horizon.py [--runs 30] [--seed 11] [--measurement camera]
        [--experiments E1,E2,E3,E4] [--horizons 1,2,3] [--steps 30]
"""

from __future__ import annotations

import numpy as np

from bve_mj.campaigns.paper import run_synthetic
from bve_mj.cli.script import SEED, ScriptParser, guarded, integer, integers, names
from bve_mj.config import Settings, with_overrides
from bve_mj.config.experiments import EXPERIMENTS


def main() -> None:
    ap = ScriptParser()
    ap.add_argument("--runs", type=integer(1), default=30)
    ap.add_argument("--seed", type=SEED, default=11)
    ap.add_argument("--measurement", default="camera", choices=("camera", "range"))
    ap.add_argument("--experiments", type=names(EXPERIMENTS), default=["E1", "E2", "E3", "E4"])
    ap.add_argument("--horizons", type=integers(1, 6), default=[1, 2, 3])
    ap.add_argument("--steps", type=integer(1), default=None)
    args = ap.parse_args()
    chosen = args.experiments
    rows: list[tuple[str, dict[str, object]]] = [
        (f"bve H={h}" if h != 1 else "bve greedy", {"kind": "bve", "horizon": h}) for h in args.horizons
    ]
    rows += [("circle", {"kind": "circle"}), ("random", {"kind": "random"})]
    print(
        f"{args.measurement} measurement, {args.runs} runs per experiment, seed {args.seed}: "
        "Euclidean error mean / median / the final covariance's rms sqrt(tr P) (mean) [mm], plan ms median"
    )
    print(f"{'planner':<12}" + "".join(f"{n:>22}" for n in chosen))
    errors: dict[str, dict[str, np.ndarray]] = {}
    for label, planner in rows:
        s = with_overrides(
            Settings(),
            measurement={"kind": args.measurement},
            planner=planner,
            protocol={"steps": args.steps} if args.steps else {},
        )
        cells = []
        errors[label] = {}
        for n in chosen:
            recs = [
                run_synthetic(s.for_world("synthetic"), EXPERIMENTS[n], args.seed, r)
                for r in range(args.runs)
            ]
            e = np.array([r["error_mm"] for r in recs])
            rms = np.array(
                [1e3 * np.sqrt(np.trace(r["cov_m2"])) for r in recs]
            )  # the filter's expected error
            errors[label][n] = rms
            ms = float(np.median(np.concatenate([r["plan_ms"] for r in recs])))
            cells.append(f"{e.mean():6.3f}/{np.median(e):6.3f}/{rms.mean():6.3f} {ms:4.1f}ms")
        print(f"{label:<12}" + "".join(f"{c:>22}" for c in cells), flush=True)
    greedy = errors["bve greedy"]
    for label in errors:
        if label.startswith("bve H="):
            better = [f"{n}: {100 * np.mean(errors[label][n] < greedy[n]):.0f}%" for n in chosen]
            print(f"{label}: runs whose sqrt(tr P) is below the greedy BVE's: " + "; ".join(better))


if __name__ == "__main__":
    guarded(main)
