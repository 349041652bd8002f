"""Can a claim be honest in the mean and never confidently wrong at once? Read from a suite run.

    bve-mj scenarios --seeds 20 --seed S --json suite.json
    python benchmarks/honesty_tails.py suite.json

Per scenario, from every episode's NEES (the claim's, and the filter's own before the claim
adds the fruit's offset and its scales): the mean and median NEES (an honest 3-D claim: mean 3,
median 2.37), and what a claim scaled to be honest in the mean would do. Scaling the
scenario's claims by k = mean NEES / 3 (an oracle: k is chosen after seeing the errors, per
scenario) makes its mean NEES 3 exactly; ``silent@k`` counts the episodes that end with a
success outcome and the truth outside the scaled claim's 99.9% ellipsoid, beside ``silent``
(the claim as made). Where ``silent@k`` > ``silent``, the errors are heavy-tailed within the
scenario: no single Gaussian scale meets both targets (mean NEES in the band, no confident
wrong answer).
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np

from bve_mj.campaigns.scenarios import SILENT_NEES

SUCCESS = ("converged", "stable", "approached")
CHI2_3_MEDIAN = 2.366


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("suite_json", type=Path, help="a `bve-mj scenarios --json` file")
    args = ap.parse_args()
    try:
        doc = json.loads(args.suite_json.read_text())
        scenarios = doc["scenarios"]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        ap.error(f"suite_json: {args.suite_json} is not a `bve-mj scenarios --json` file ({exc})")
    print(f"{'scenario':22s} {'n':>3s} {'mean':>7s} {'median':>7s} {'filter':>7s} {'silent':>6s} "
          f"{'k':>6s} {'silent@k':>8s}")  # fmt: skip
    totals = [0, 0, 0]
    for name, s in scenarios.items():
        runs = [r for r in s["runs"] if r.get("nees") is not None and math.isfinite(r["nees"])]
        if not runs:
            continue
        nees = np.array([r["nees"] for r in runs])
        success = np.array([r["outcome"] in SUCCESS for r in runs])
        filt = [r["filter_nees"] for r in runs if r.get("filter_nees") is not None]
        k = float(np.mean(nees)) / 3.0
        silent = int(np.sum(success & (nees > SILENT_NEES)))
        silent_k = int(np.sum(success & (nees / k > SILENT_NEES)))
        totals = [totals[0] + len(runs), totals[1] + silent, totals[2] + silent_k]
        filt_mean = f"{np.mean(filt):7.2f}" if filt else f"{'-':>7s}"
        print(f"{name:22s} {len(runs):3d} {np.mean(nees):7.2f} {np.median(nees):7.2f} {filt_mean} "
              f"{silent:6d} {k:6.2f} {silent_k:8d}")  # fmt: skip
    print(f"{'all':22s} {totals[0]:3d} {'':7s} {'':7s} {'':7s} {totals[1]:6d} {'':6s} {totals[2]:8d}")
    print(
        f"(honest: mean 3, median {CHI2_3_MEDIAN}; silent: success outcome, NEES > {SILENT_NEES} "
        "(outside the 99.9% ellipsoid); k: the claim's scale for a mean NEES of 3)"
    )


if __name__ == "__main__":
    main()
