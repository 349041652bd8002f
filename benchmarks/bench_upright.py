"""Upright eye-in-hand images: the image's roll at every view, with the preference on and off.

    python benchmarks/bench_upright.py [--scenarios clean,truss_cluster] [--episodes 10] [--seed 4242]

Runs one-target episodes of suite scenarios (episode ``i`` seeded as the suite seeds it) twice,
with ``planner.upright_weight`` at 0.1 (MuJoCo's default) and at 0 (the roll left free), and
prints per scenario and setting: views, the image's |roll| at the views (the angle about the
optical axis from the world's up to the image's up: 0 upright, 180 deg the floor at the top;
views looking within ~6 deg of vertical have no up and are left out) as median, 90th
percentile and shares above 45 and 90 deg, and the final error (median, mm).
Target (issue 15): videos with the floor at the bottom, never at the cost of reachability.
"""

from __future__ import annotations

import math

import numpy as np

from bve_mj.campaigns.scenarios import load_suite
from bve_mj.campaigns.spec import episode_seed
from bve_mj.cli.script import SEED, ScriptParser, guarded, integer
from bve_mj.config import with_overrides
from bve_mj.loop.mujoco import run_mujoco_episode
from bve_mj.robot.ik import image_roll_rad


def main() -> None:
    ap = ScriptParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenarios", default="clean,truss_cluster")
    ap.add_argument("--episodes", type=integer(1), default=10)
    ap.add_argument("--seed", type=SEED, default=4242)
    args = ap.parse_args()
    for sc in load_suite(only=args.scenarios.split(",")):
        base = sc.settings(None, None, None)
        for label, weight in (("upright", 0.1), ("roll free", 0.0)):
            settings = with_overrides(base, planner={"upright_weight": weight})
            rolls: list[float] = []
            views, errors = [], []
            for run in range(args.episodes):
                ep = run_mujoco_episode(settings, episode_seed(args.seed, run))
                views.append(len(ep.result.views))
                errors.append(1e3 * float(np.linalg.norm(ep.result.final.centre_m - ep.info.target.centre_m)))
                for v in ep.result.views:
                    R = (v.world or {}).get("camera_rotation")
                    roll = None if R is None else image_roll_rad(np.asarray(R))
                    if roll is not None:
                        rolls.append(abs(math.degrees(roll)))
            r = np.array(rolls)
            print(
                f"{sc.name:14s} {label:9s} views {np.mean(views):4.1f}  |roll| median {np.median(r):5.1f} "
                f"p90 {np.percentile(r, 90):5.1f} deg, >45: {100 * np.mean(r > 45):3.0f}%, "
                f">90: {100 * np.mean(r > 90):3.0f}%  error median {np.median(errors):.2f} mm",
                flush=True,
            )


if __name__ == "__main__":
    guarded(main)
