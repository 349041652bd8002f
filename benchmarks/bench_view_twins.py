"""How the detector's errors in two views correlate with the distance between the cameras.

    python benchmarks/bench_view_twins.py [--only clean,beefsteak,...] [--scenes 4]
                                          [--views 12] [--seed 77] [--workers 2]

Each drawn view of a scenario's target (as ``bve-mj calibrate`` draws them) gets twins from a
camera displaced by 0-40 mm across the viewing direction (:mod:`bve_mj.campaigns.twin_views`).
Prints per displacement the pairs, the angle between the views and the robust correlation of
their errors (bearing; apparent radius) beside what the shipped noise model says (``model``),
then the nearby part fitted to them (``nearby`` a, ``length_m`` ℓ of
:class:`~bve_mj.estimation.view_correlation.ViewCorrelation`), the figures the shipped
``bve_mj/data/noise_model.json`` carries.
"""

from __future__ import annotations

import math

import numpy as np

from bve_mj.campaigns.scenarios import load_suite
from bve_mj.campaigns.twin_views import fit_nearby, twin_correlations, twin_rows
from bve_mj.cli.script import SEED, ScriptParser, guarded, integer
from bve_mj.config import Settings
from bve_mj.estimation.noise import load_noise_model

SCENES = "clean,beefsteak,ripe_truss,truss_chain,truss_cluster,cherry_truss,heavy_occlusion,plum"


def main() -> None:
    ap = ScriptParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default=SCENES, help=f"comma-separated scenarios (default {SCENES})")
    ap.add_argument("--scenes", type=integer(1), default=4, help="seeded scenes per scenario (default 4)")
    ap.add_argument("--views", type=integer(1), default=12, help="drawn views per scene (default 12)")
    ap.add_argument("--seed", type=SEED, default=77, help="base seed (default 77)")
    ap.add_argument("--workers", type=integer(1, 64), default=2, help="local processes (default 2)")
    args = ap.parse_args()
    suite = load_suite(only=args.only.split(","))
    rows = twin_rows(suite, scenes=args.scenes, views=args.views, seed=args.seed, workers=args.workers)
    noise = load_noise_model(Settings().measurement.noise_model)
    table = twin_correlations(rows) if rows else []
    if len(table) < 3:
        ap.error(f"--views: {len(rows)} twin pairs, too few to fit (10 at three displacements): more views")
    print(f"{len(rows)} twin pairs: {args.only}, {args.scenes} scenes x {args.views} views, seed {args.seed}")
    head = (("delta mm", 8), ("pairs", 5), ("angle deg", 9), ("centre rho", 10), ("model", 6))
    print(" ".join(f"{h:>{w}s}" for h, w in head) + f" {'radius rho':>10s} {'model':>6s}")
    for t in table:
        angle = math.degrees(math.acos(min(1.0, t.cos)))
        mc, mr = (_rho(c, t.cos, t.delta_m) for c in (noise.centre_correlation, noise.radius_correlation))
        print(f"{1e3 * t.delta_m:8.0f} {t.pairs:5d} {angle:9.2f} {t.centre:10.2f} {mc:6.2f} ", end="")
        print(f"{t.radius:10.2f} {mr:6.2f}")
    for name, corr in (("centre", noise.centre_correlation), ("radius", noise.radius_correlation)):
        fit = fit_nearby(table, corr, name)
        print(
            f"{name}: weight {corr.weight:.3f}, width {corr.width:.4f} (shipped); "
            f"fitted nearby {fit.nearby:.3f}, length_m {fit.length_m:.4f}"
        )


def _rho(corr: object, cos: float, delta_m: float) -> float:
    from bve_mj.estimation.view_correlation import ViewCorrelation

    assert isinstance(corr, ViewCorrelation)
    return float(corr.rho(np.array(cos)) + corr.rho_near(np.array(delta_m)))


if __name__ == "__main__":
    guarded(main)
