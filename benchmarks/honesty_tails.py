"""Can a claim be honest in the mean and never confidently wrong at once? Read from a suite run.

    bve-mj scenarios --seeds 20 --seed S --json suite.json
    python benchmarks/honesty_tails.py suite.json

Per scenario, from every episode's NEES (the claim's, and the filter's own before the claim
adds the fruit's offset and its scales): the mean and median NEES (an honest 3-D claim: mean 3,
median 2.37), and what a claim scaled to be honest in the mean would do. Scaling the
scenario's claims by k = mean NEES / 3 (an oracle: k is chosen after seeing the errors, per
scenario) makes its mean NEES 3 exactly; ``silent@k`` counts the episodes that end with a
success outcome and the truth outside the scaled Gaussian claim's 99.9% ellipsoid, beside
``silent`` (the claim as made: outside its 99.9% region, its bound's ellipsoid where the
claim is a Student-t, ``claim_dof`` in the rows). Where ``silent@k`` > ``silent``, the errors
are heavy-tailed within the scenario: no single Gaussian scale meets both targets (mean NEES
in the band, no confident wrong answer).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from bve_mj.campaigns.scenarios import SILENT_NEES, SILENT_PROBABILITY
from bve_mj.cli.script import ScriptParser, guarded
from bve_mj.estimation.claim_shape import claim_region
from bve_mj.loop.outcomes import Outcome

SUCCESS = frozenset(o.value for o in Outcome if o.success)  # a stop rule said done
CHI2_3_MEDIAN = 2.366


Row = tuple[float, bool, float | None, float]  # (claim NEES, success outcome, filter NEES, 99.9% region)


def _number(x: object) -> float | None:
    """x as a finite float, None where it is none (missing, null, not finite, not a number)."""
    if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x):
        return None
    return float(x)


def _read(path: Path) -> dict[str, list[Row]]:
    """Per scenario, its episodes' (NEES, success, filter NEES); raises ValueError on a file
    that is not a suite's JSON."""
    doc = json.loads(path.read_text())
    scenarios = doc.get("scenarios") if isinstance(doc, dict) else None
    if not isinstance(scenarios, dict):
        raise ValueError("no 'scenarios' object")
    out: dict[str, list[Row]] = {}
    for name, s in scenarios.items():
        runs = s.get("runs") if isinstance(s, dict) else None
        if not isinstance(runs, list) or not all(isinstance(r, dict) for r in runs):
            raise ValueError(f"scenario {name!r} has no list of runs")
        rows = []
        for r in runs:
            nees = _number(r.get("nees"))
            if nees is not None:
                region = claim_region(_number(r.get("claim_dof")), SILENT_PROBABILITY)
                rows.append((nees, r.get("outcome") in SUCCESS, _number(r.get("filter_nees")), region))
        out[str(name)] = rows
    return out


def main() -> None:
    ap = ScriptParser()
    ap.add_argument("suite_json", type=Path, help="a `bve-mj scenarios --json` file")
    args = ap.parse_args()
    try:
        scenarios = _read(args.suite_json)
    except (OSError, ValueError) as exc:
        ap.error(f"suite_json: got '{args.suite_json}'; allowed: a `bve-mj scenarios --json` file ({exc})")
    print(f"{'scenario':22s} {'n':>3s} {'mean':>7s} {'median':>7s} {'filter':>7s} {'silent':>6s} "
          f"{'k':>6s} {'silent@k':>8s}")  # fmt: skip
    totals = [0, 0, 0]
    for name, rows in scenarios.items():
        if not rows:
            continue
        nees = np.array([r[0] for r in rows])
        success = np.array([r[1] for r in rows])
        filt = [r[2] for r in rows if r[2] is not None]
        k = float(np.mean(nees)) / 3.0
        silent = int(np.sum(success & (nees > np.array([r[3] for r in rows]))))
        silent_k = int(np.sum(success & (nees / k > SILENT_NEES))) if k > 0.0 else silent
        totals = [totals[0] + len(rows), totals[1] + silent, totals[2] + silent_k]
        filt_mean = f"{np.mean(filt):7.2f}" if filt else f"{'-':>7s}"
        print(f"{name:22s} {len(rows):3d} {np.mean(nees):7.2f} {np.median(nees):7.2f} {filt_mean} "
              f"{silent:6d} {k:6.2f} {silent_k:8d}")  # fmt: skip
    print(f"{'all':22s} {totals[0]:3d} {'':7s} {'':7s} {'':7s} {totals[1]:6d} {'':6s} {totals[2]:8d}")
    print(
        f"(honest: mean 3, median {CHI2_3_MEDIAN} for a Gaussian claim; silent: success outcome, the truth "
        f"outside the claim's 99.9% region (NEES > {SILENT_NEES} for a Gaussian one); silent@k: outside "
        "the 99.9% ellipsoid of the Gaussian of k times less; k: the claim's scale for a mean NEES of 3)"
    )


if __name__ == "__main__":
    guarded(main)
