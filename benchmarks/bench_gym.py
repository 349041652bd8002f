"""The Gymnasium environment's speed: one env step (move, render, detect, fuse) and one reset.

    python benchmarks/bench_gym.py [--steps 60] [--scenario clean]

Random actions (seeded), a reset whenever an episode ends; prints the median step time with
the world's own split (IK, control in physics, render, detect) and the median reset time.
Target (issue 15): one env step <= 60 ms on the 2-core development machine, render included.
"""

from __future__ import annotations

import time

import numpy as np

from bve_mj.cli.script import ScriptParser, guarded, integer
from bve_mj.gym.env import ViewPlanningEnv


def main() -> None:
    ap = ScriptParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=integer(1), default=60)
    ap.add_argument("--scenario", default="clean")
    args = ap.parse_args()
    env = ViewPlanningEnv(scenario=args.scenario)
    env.action_space.seed(0)
    resets, steps, split = [], [], []
    seed = 0

    def reset() -> None:
        nonlocal seed
        t0 = time.perf_counter()
        env.reset(seed=seed)
        resets.append(time.perf_counter() - t0)
        seed += 1

    reset()
    for _ in range(args.steps):
        t0 = time.perf_counter()
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        steps.append(time.perf_counter() - t0)
        assert env._parts is not None
        t = env._parts.world.last.timings
        split.append((t.ik_s, t.control_s, t.render_s, t.detect_s))
        if terminated or truncated:
            reset()
    ik, control, render, detect = (1e3 * float(np.median(c)) for c in zip(*split, strict=True))
    print(
        f"{args.scenario}: {len(steps)} steps, median step {1e3 * float(np.median(steps)):.1f} ms "
        f"(IK {ik:.1f}, control {control:.1f}, render {render:.1f}, detect {detect:.1f} ms); "
        f"{len(resets)} resets, median {float(np.median(resets)):.2f} s"
    )
    env.close()


if __name__ == "__main__":
    guarded(main)
