"""Whether every-fruit tracks need the dispute rule of one-target episodes: per localised fruit,
a dispute standing at the end, and whether its claim is silent.

    python benchmarks/bench_fruit_disputes.py [--seed 3456] [--episodes 20]
        [--only ripe_truss,truss_chain,truss_cluster,cherry_truss,plant_trusses]

Runs every-fruit episodes of the suite's truss scenarios (episode ``i`` seeded as the suite
seeds it). Each track's accepted detections are read where the loop makes its claim
(``bve_mj.loop.every_fruit.claimed``, wrapped here to keep the last ``innovations`` and
``directions`` of every track); a dispute stands on a track when, as
:meth:`bve_mj.loop.stops.StopRules.standing_dispute` judges one-target views, its last
detection whose NIS exceeded the 99.9% χ² quantile (3 components) has no later detection from
a direction :data:`bve_mj.loop.stops.SETTLE_DEG` or more away (seen from the fruit). A track's
k-th innovation belongs to its (k+1)-th direction (the first started it); tracks that merged
may pair them out of order, which the count beside says. Prints, per scenario, the localised
fruit, those with a dispute standing, the mean claim NEES of both groups and the silent fruit
(claimed localised with the truth outside the 99.9% ellipsoid).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

import bve_mj.loop.every_fruit as every_fruit
from bve_mj.campaigns.scenarios import load_suite
from bve_mj.campaigns.spec import episode_seed
from bve_mj.cli.script import SEED, ScriptParser, guarded, integer
from bve_mj.config import with_overrides
from bve_mj.estimation.metrics import chi2_quantile
from bve_mj.loop.mujoco_fruits import run_every_fruit_episode
from bve_mj.loop.stops import SETTLE_DEG

SCENES = "ripe_truss,truss_chain,truss_cluster,cherry_truss,plant_trusses"


def standing_dispute(innovations: list[tuple[float, float]], directions: list[np.ndarray]) -> float | None:
    """The NIS of the dispute standing on a track at the end, or None."""
    limit, cos_settle = float(chi2_quantile(0.999, 3)), math.cos(math.radians(SETTLE_DEG))
    standing: tuple[float, np.ndarray] | None = None
    for k, (nis, _) in enumerate(innovations):
        if k + 1 >= len(directions):
            break
        d = directions[k + 1]
        if standing is not None and float(d @ standing[1]) <= cos_settle:
            standing = None
        if nis > limit:
            standing = (nis, d)
    return None if standing is None else standing[0]


def main() -> None:
    ap = ScriptParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seed", type=SEED, default=3456)
    ap.add_argument("--episodes", type=integer(1), default=20)
    ap.add_argument("--only", default=SCENES)
    args = ap.parse_args()
    history: dict[int, tuple[list[tuple[float, float]], list[np.ndarray]]] = {}
    claimed = every_fruit.claimed

    def keeping(track: Any, *a: Any, **k: Any) -> Any:
        history[track.id] = (list(track.innovations), [d.copy() for d in track.directions])
        return claimed(track, *a, **k)

    every_fruit.claimed = keeping
    silent_nees = float(chi2_quantile(0.999, 3))
    suite = {sc.name: sc for sc in load_suite(only=args.only.split(","))}
    print(f"seed {args.seed}, {args.episodes} episodes a scenario")
    head = ("localised", "disputed", "NEES disputed", "NEES others", "silent", "merged")
    print(f"{'scenario':15s} " + " ".join(f"{h:>{max(len(h), 6)}s}" for h in head))
    for name in args.only.split(","):
        base = suite[name].settings("camera", None, "centre_radius")
        settings = with_overrides(base, tracking={"fruits": "all"})
        disputed: list[float] = []
        others: list[float] = []
        silent = merged = 0
        for run in range(args.episodes):
            history.clear()
            episode = run_every_fruit_episode(settings, episode_seed(args.seed, run))
            matches, _, _ = episode.matches()
            for m in matches:
                if m.track is None or not m.track.localised:
                    continue
                innovations, directions = history.get(m.track.id, ([], []))
                merged += len(directions) != len(innovations) + 1
                (disputed if standing_dispute(innovations, directions) is not None else others).append(m.nees)
                silent += m.nees > silent_nees
        n = len(disputed) + len(others)
        print(
            f"{name:15s} {n:9d} {len(disputed):8d} {np.mean(disputed) if disputed else math.nan:13.2f} "
            f"{np.mean(others) if others else math.nan:11.2f} {silent:6d} {merged:6d}",
            flush=True,
        )


if __name__ == "__main__":
    guarded(main)
