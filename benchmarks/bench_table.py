"""Wall time of the 8-experiment × 100-run synthetic table (E1-E4, E6-E9).

    python benchmarks/bench_table.py [--workers 2] [--runs 100]

Target (issue 2): at most 60 s on 2 cores.
"""

from __future__ import annotations

import time

from bve_mj.campaigns.paper import run_table
from bve_mj.cli.script import ScriptParser, guarded, integer
from bve_mj.config import Settings, with_overrides
from bve_mj.config.experiments import EXPERIMENTS


def main() -> None:
    ap = ScriptParser()
    ap.add_argument("--workers", type=integer(1, 1024), default=2)
    ap.add_argument("--runs", type=integer(1), default=100)
    args = ap.parse_args()
    exps = [EXPERIMENTS[n] for n in ("E1", "E2", "E3", "E4", "E6", "E7", "E8", "E9")]
    for measurement in ("range", "camera"):
        s = with_overrides(Settings(), measurement={"kind": measurement})
        t0 = time.perf_counter()
        res = run_table(s, exps, args.runs, 0, workers=args.workers)
        wall = time.perf_counter() - t0
        steps = args.runs * len(exps) * s.protocol.steps
        print(
            f"{measurement:<7} {len(exps)} experiments x {args.runs} runs x {s.protocol.steps} steps "
            f"on {args.workers} workers: {wall:.1f} s ({wall / steps * 1e3 * args.workers:.2f} ms per step "
            f"per worker); median plan ms {min(v.metrics['plan_ms_median'] for v in res.values()):.2f}"
            f"-{max(v.metrics['plan_ms_median'] for v in res.values()):.2f}"
        )


if __name__ == "__main__":
    guarded(main)
