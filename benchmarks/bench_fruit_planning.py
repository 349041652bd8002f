"""The every-fruit planning step against the number of tracks it plans for.

    python benchmarks/bench_fruit_planning.py [--scenario truss_cluster[,ripe_truss,...]]
                                              [--episodes 5] [--seed 8080]

Runs ``bve-mj episode --fruits all`` episodes of each suite scenario (episode ``i`` seeded as
the suite seeds it) and prints, per scenario, the planning time of each view after the first
(every candidate's BVE with the arm, the unhiding views, the clearance checks; the views
that explore the zone too) by the number of tracks alive when it was planned: median, p90
and count. Run it alone on the machine: the times are wall-clock.
Target (issue 14): a planning step with 8 tracks at most 30 ms (median).
"""

from __future__ import annotations

import itertools

import numpy as np

from bve_mj.campaigns.scenarios import load_suite
from bve_mj.campaigns.spec import episode_seed
from bve_mj.cli.script import SEED, ScriptParser, guarded, integer
from bve_mj.config import with_overrides
from bve_mj.errors import BveError
from bve_mj.loop.mujoco_fruits import run_every_fruit_episode

_BANDS = ((1, 3), (4, 7), (8, 99))  # tracks alive when the view was planned


def _cell(ms: list[float]) -> str:
    if not ms:
        return f"{'-':>7} {'-':>6} {0:>5}"
    return f"{np.median(ms):7.1f} {np.percentile(ms, 90):6.0f} {len(ms):5d}"


def main() -> None:
    ap = ScriptParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="truss_chain,truss_cluster,ripe_truss,cherry_truss,plant_trusses")
    ap.add_argument("--episodes", type=integer(1), default=5)
    ap.add_argument("--seed", type=SEED, default=8080)
    args = ap.parse_args()
    try:
        suite = load_suite(only=args.scenario.split(","))
    except BveError as exc:
        ap.error(f"--scenario: {exc}")
    names = [f"{lo}-{hi}" if hi < 99 else f">={lo}" for lo, hi in _BANDS]
    bands = "".join(f" | {name:>7} tracks: median    p90 views" for name in names)
    print(f"planning ms per view, {args.episodes} episodes a scenario, seed {args.seed}")
    print(f"{'scenario':<14} {'all: median':>11} {'p90':>6} {'views':>5}{bands}")
    every: list[tuple[int, float]] = []
    for sc in suite:
        settings = with_overrides(sc.settings("camera", None, "centre_radius"), tracking={"fruits": "all"})
        rows: list[tuple[int, float]] = []  # (tracks alive, plan ms) per planned view
        for run in range(args.episodes):
            views = run_every_fruit_episode(settings, episode_seed(args.seed, run)).result.views
            rows += [(len(before.fruits), 1e3 * v.plan_s) for before, v in itertools.pairwise(views)]
        every += rows
        print(_line(sc.name, rows), flush=True)
    if len(suite) > 1:
        print(_line("all", every))


def _line(name: str, rows: list[tuple[int, float]]) -> str:
    ms = [m for _, m in rows]
    cells = "".join(f" | {'':>14}{_cell([m for n, m in rows if lo <= n <= hi])}" for lo, hi in _BANDS)
    return f"{name:<14} {_cell(ms)}{cells}"


if __name__ == "__main__":
    guarded(main)
