"""Localisation error per detector: the built-in colour detector against synthetic boxes.

    python benchmarks/bench_detectors.py [--scenario clean] [--seeds 10] [--seed 0]
        [--kinds builtin,synthetic_boxes] [--box-noise-px 2] [--miss-p 0] [--false-positives 0]

Every kind runs the same ``--seeds`` episodes of the scenario (episode ``i`` seeded as the
scenario suite seeds it, ``episode_seed(seed, i)``: ``bve-mj episode --config FILE --seed <it>
--detector KIND`` replays one). ``synthetic_boxes`` are the true boxes of the fruit in view
with ``--box-noise-px`` Gaussian corner noise, ``--miss-p`` misses and ``--false-positives``
false boxes per image, measured by the box adapter. Prints per kind: the median, 95th
percentile and largest final error [mm], the outcomes, the median views, the median detector
time per view [ms] and the wall time. One process, one BLAS thread (as the suite's workers).
"""

from __future__ import annotations

import time
from collections import Counter
from typing import get_args

import numpy as np

from bve_mj.campaigns.scenarios import load_suite
from bve_mj.campaigns.spec import episode_seed
from bve_mj.cli.script import SEED, ScriptParser, guarded, integer, names, number
from bve_mj.config import with_overrides
from bve_mj.config.fields import DetectorKind
from bve_mj.loop.mujoco import run_mujoco_episode


def main() -> None:
    ap = ScriptParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="clean", help="a scenario of the suite (default clean)")
    ap.add_argument("--seeds", type=integer(1), default=10, help="episodes per detector kind (default 10)")
    ap.add_argument("--seed", type=SEED, default=0, help="the suite seed the episodes' seeds come from")
    kinds = names(get_args(DetectorKind))
    ap.add_argument("--kinds", type=kinds, default=["builtin", "synthetic_boxes"], help="detector kinds")
    ap.add_argument(
        "--box-noise-px", type=number(0.0), default=2.0, help="synthetic boxes: corner sigma [px]"
    )
    ap.add_argument("--miss-p", type=number(0.0, 1.0), default=0.0, help="synthetic boxes: miss probability")
    ap.add_argument(
        "--false-positives", type=number(0.0), default=0.0, help="synthetic boxes: false boxes per image"
    )
    args = ap.parse_args()
    (scenario,) = load_suite(only=[args.scenario])
    base = scenario.settings()
    seeds = [episode_seed(args.seed, i) for i in range(args.seeds)]
    print(
        f"{args.scenario}: {args.seeds} episodes per kind (suite seed {args.seed}); synthetic boxes: "
        f"noise {args.box_noise_px:g} px, miss {args.miss_p:g}, false {args.false_positives:g}/image"
    )
    print(
        f"{'kind':<16} {'median mm':>9} {'p95 mm':>8} {'max mm':>8} {'views':>5} {'detect ms':>9} "
        f"{'wall s':>7}  outcomes"
    )
    for kind in args.kinds:
        settings = with_overrides(
            base,
            detector={
                "kind": kind,
                "box_noise_px": args.box_noise_px,
                "miss_p": args.miss_p,
                "false_positives": args.false_positives,
            },
        )
        errors, views, detect_ms = [], [], []
        outcomes: Counter[str] = Counter()
        t0 = time.perf_counter()
        for s in seeds:
            ep = run_mujoco_episode(settings, s)
            errors.append(ep.final_error_mm)
            outcomes[str(ep.result.outcome)] += 1
            doc = ep.to_json()
            views.append(len(doc["views"]))
            detect_ms += [1e3 * v["timings_s"]["detect_s"] for v in doc["views"] if "timings_s" in v]
        wall = time.perf_counter() - t0
        e = np.array(errors)
        shown = ", ".join(f"{k} {n}" for k, n in outcomes.most_common())
        print(
            f"{kind:<16} {np.median(e):9.2f} {np.percentile(e, 95):8.2f} {e.max():8.2f} "
            f"{np.median(views):5.0f} {np.median(detect_ms):9.1f} {wall:7.1f}  {shown}"
        )


if __name__ == "__main__":
    guarded(main)
