"""How well the every-fruit detector separates touching fruit, view by view, against the truth.

    python benchmarks/bench_instances.py [--only truss_cluster,ripe_truss,...] [--scenes 6]
                                         [--views 25] [--seed 71] [--workers 2]

Renders ``--views`` views of ``--scenes`` seeded scenes of each scenario from poses the arm
reaches, as ``bve-mj calibrate --every-fruit`` does (the same views: ``--seed`` is its base
seed), and runs both detectors on them: the single-target one on the target (``target``
rows) and the every-fruit one on every fruit of the truss (``every`` rows). A row is a fruit
the detector found in a view (measured or refused, matched to the true fruit nearest its
circle); a fruit it did not find at all gives none. Per scenario and detector it prints: the
rows, the share measured, and the share of measurements off by more than 10% of the true
apparent radius in size (``r>10%``) and in the centre's position (``c>10%``): the gross
errors a truss's hidden fruit suffer when an occluder's edge joins their silhouette (measured
small and off-centre, view after view: the tracker cannot average them away), then the
median |size error| [px]. The yardstick for the detector behind issue 14's `truss_cluster`
coverage: more measured, fewer gross.
"""

from __future__ import annotations

import math

import numpy as np

from bve_mj.campaigns.calibration import run_calibration
from bve_mj.campaigns.scenarios import load_suite
from bve_mj.cli.script import SEED, ScriptParser, guarded, integer

SCENES = "truss_cluster,ripe_truss,truss_chain,cherry_truss,plant_trusses"


def _line(name: str, source: str, rows: list[dict]) -> str:
    measured = [r for r in rows if r["detected"]]
    if not measured:
        return f"{name:15s} {source:6s} {len(rows):5d} {0.0:9.1%} {'-':>6s} {'-':>6s} {'-':>8s}"
    size = np.array([abs(r["err_alpha_px"]) / r["radius_px"] for r in measured])
    centre = np.array([math.hypot(r["err_u_px"], r["err_v_px"]) / r["radius_px"] for r in measured])
    median_px = float(np.median([abs(r["err_alpha_px"]) for r in measured]))
    return (
        f"{name:15s} {source:6s} {len(rows):5d} {len(measured) / len(rows):9.1%} "
        f"{np.mean(size > 0.1):6.1%} {np.mean(centre > 0.1):6.1%} {median_px:8.2f}"
    )


def main() -> None:
    ap = ScriptParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default=SCENES, help=f"comma-separated scenarios (default {SCENES})")
    ap.add_argument("--scenes", type=integer(1), default=6, help="seeded scenes per scenario (default 6)")
    ap.add_argument("--views", type=integer(1), default=25, help="views per scene (default 25)")
    ap.add_argument("--seed", type=SEED, default=71, help="base seed (default 71)")
    ap.add_argument("--workers", type=integer(1, 64), default=2, help="local processes (default 2)")
    args = ap.parse_args()
    suite = load_suite(only=args.only.split(","))
    data = run_calibration(
        suite, scenes=args.scenes, views=args.views, seed=args.seed, workers=args.workers, every_fruit=True
    )
    print(f"{args.scenes} scenes x {args.views} views a scenario, seed {args.seed}, wall {data.wall_s:.0f} s")
    head = (("rows", 5), ("measured", 9), ("r>10%", 6), ("c>10%", 6), ("|dr| px", 8))
    print(f"{'scenario':15s} {'detector':6s} " + " ".join(f"{h:>{w}s}" for h, w in head))
    for sc in suite:
        for source in ("target", "every"):
            rows = [
                r for r in data.rows
                if r["scenario"] == sc.name and (r.get("source") == "every") == (source == "every")
            ]  # fmt: skip
            if rows:
                print(_line(sc.name, source, rows), flush=True)


if __name__ == "__main__":
    guarded(main)
