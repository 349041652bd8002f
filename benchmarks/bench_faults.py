"""The fault-injection suite at scale: MuJoCo episodes in every scenario of the suite (trusses,
cherry, beefsteak, plum, occlusion, light, realistic sensors) with the faults preset of
``examples/scenarios/faults.toml`` laid over each scenario's settings.

    python benchmarks/bench_faults.py [--episodes 1000] [--workers 2] [--seed 0] [--out DIR]

Counts what must be zero (crashes, non-finite beliefs, joint-limit violations beyond 1e-3 rad,
a camera inside the fruit) and the silent failures (a success outcome, converged, stable or
approached, with the truth outside the final belief's 99.9% ellipsoid), per scenario and in
all; the outcomes and the final error's median / p95 / max. Each scenario is a campaign in
its own directory under ``--out`` (resumable: the same command continues an interrupted run).
"""

from __future__ import annotations

import math
import tempfile
import time
from pathlib import Path

import numpy as np

from bve_mj.campaigns.runner import run_campaign
from bve_mj.campaigns.scenarios import SILENT_PROBABILITY, load_suite
from bve_mj.campaigns.spec import CampaignSpec
from bve_mj.cli.script import SEED, ScriptParser, guarded, integer
from bve_mj.config import load_settings
from bve_mj.estimation.claim_shape import claim_region
from bve_mj.loop.outcomes import Outcome
from bve_mj.threads import one_blas_thread

FAULTS = Path(__file__).resolve().parents[1] / "examples" / "scenarios" / "faults.toml"


def main() -> None:
    ap = ScriptParser(description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "--episodes", type=integer(1), default=1000, help="in all, spread evenly over the scenarios"
    )
    ap.add_argument("--workers", type=integer(1, 1024), default=2)
    ap.add_argument("--seed", type=SEED, default=0)
    ap.add_argument("--out", type=Path, default=None, help="campaign directories (default: a temporary one)")
    args = ap.parse_args()
    scenarios = load_suite()
    runs = math.ceil(args.episodes / len(scenarios))
    tmp = tempfile.TemporaryDirectory() if args.out is None else None
    out = Path(tmp.name) if tmp is not None else args.out
    t0 = time.perf_counter()
    every: list[dict] = []
    print(f"fault suite: {len(scenarios)} scenarios x {runs} episodes, {FAULTS.name}, seed {args.seed}")
    print(f"{'scenario':<22}{'eps':>5}{'crash':>6}{'NaN':>5}{'limit':>6}{'inside':>7}{'silent':>7}"
          f"{'median':>8}{'p95':>8}{'max mm':>8}  outcomes")  # fmt: skip
    with one_blas_thread():
        for sc in scenarios:
            settings = load_settings(FAULTS, base=sc.settings("camera", None, None))
            spec = CampaignSpec(experiments=("E1",), worlds=("mujoco",), measurements=("camera",), runs=runs,
                                seed=args.seed)  # fmt: skip
            result = run_campaign(settings, spec, out / sc.name, workers=args.workers)
            rows = list(result.rows)
            every += rows
            _line(sc.name, rows, settings.scene.radius_range_m[0])
    print("-" * 100)
    _line("all", every, 0.0)
    print(f"wall time {time.perf_counter() - t0:.0f} s")
    if tmp is not None:
        tmp.cleanup()


def _line(name: str, rows: list[dict], min_radius_m: float) -> None:
    ok = [r for r in rows if r["outcome"] not in ("crashed", "failed")]
    crashed = len(rows) - len(ok)
    nan = sum(not r.get("belief_finite", True) for r in ok)
    limit = sum(r.get("joint_limit_violation_rad", 0.0) > 1e-3 for r in ok)
    inside = sum(r.get("min_camera_fruit_distance_m", math.inf) <= min_radius_m for r in ok)
    silent = sum(
        Outcome(r["outcome"]).success and r["nees"] > claim_region(r.get("claim_dof"), SILENT_PROBABILITY)
        for r in ok
    )
    err = np.array([r["error_mm"] for r in ok]) if ok else np.array([math.nan])
    outcomes: dict[str, int] = {}
    for r in rows:
        outcomes[r["outcome"]] = outcomes.get(r["outcome"], 0) + 1
    text = " ".join(f"{k}:{v}" for k, v in sorted(outcomes.items()))
    print(f"{name:<22}{len(rows):>5}{crashed:>6}{nan:>5}{limit:>6}{inside:>7}{silent:>7}"
          f"{np.median(err):>8.2f}{np.percentile(err, 95):>8.2f}{err.max():>8.2f}  {text}")  # fmt: skip


if __name__ == "__main__":
    guarded(main)
