"""The BVE as a policy inside the Gymnasium environment, beside a random policy, on the same
seeds: returns, views and final errors.

python examples/gym_policies.py [episodes] [scenario]      (needs: pip install 'bve_mj[gym]')
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np

import bve_mj.gym  # noqa: F401  (registers BveMj/ViewPlanning-v0)
from bve_mj.cli.script import ScriptParser, guarded, integer
from bve_mj.gym.env import ViewPlanningEnv


def run(env: gym.Env, policy: str, seed: int) -> tuple[float, int, float, str]:
    """One episode: (return, views after the start, final error [mm], how it ended)."""
    env.reset(seed=seed)
    env.action_space.seed(seed)
    total, views = 0.0, 0
    while True:  # the env truncates at the view budget
        inner = env.unwrapped
        assert isinstance(inner, ViewPlanningEnv)
        action = inner.planner_action() if policy == "bve" else env.action_space.sample()
        _, reward, terminated, truncated, info = env.step(action)
        total, views = total + float(reward), views + 1
        if terminated or truncated:
            ending = info["outcome"]
            break
    return total, views, 1e3 * info["error_m"], ending


def main(episodes: int = 3, scenario: str = "clean") -> None:
    env = gym.make("BveMj/ViewPlanning-v0", scenario=scenario)
    for policy in ("bve", "random"):
        rows = [run(env, policy, seed) for seed in range(episodes)]
        for seed, (ret, views, err, ending) in enumerate(rows):
            print(
                f"{policy:6} seed {seed}: return {ret:7.2f}, {views:2d} views, error {err:6.2f} mm, {ending}"
            )
        mean_ret, mean_views, mean_err = (float(np.mean([r[i] for r in rows])) for i in range(3))
        print(f"{policy:6} mean: return {mean_ret:7.2f}, {mean_views:4.1f} views, error {mean_err:6.2f} mm")
    env.close()


if __name__ == "__main__":
    ap = ScriptParser(description=__doc__.splitlines()[0])
    ap.add_argument("episodes", nargs="?", type=integer(1), default=3)
    ap.add_argument("scenario", nargs="?", default="clean", help="a scenario of the suite")
    args = ap.parse_args()
    guarded(lambda: main(args.episodes, args.scenario))
