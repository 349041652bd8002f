"""The Gymnasium environment: Gymnasium's own checker, the BVE as a policy, bad input."""

import numpy as np
import pytest

gym = pytest.importorskip("gymnasium")

from bve_mj.errors import ConfigError  # noqa: E402
from bve_mj.gym import ENV_ID  # noqa: E402
from bve_mj.gym.env import ViewPlanningEnv  # noqa: E402


@pytest.fixture(scope="module")
def env():
    e = ViewPlanningEnv(scenario="clean")
    yield e
    e.close()


def test_the_environment_passes_gymnasiums_checker(env):
    from gymnasium.utils.env_checker import check_env

    check_env(env, skip_render_check=True)
    made = gym.make(ENV_ID, scenario="clean")  # registered on import of bve_mj.gym
    assert isinstance(made.unwrapped, ViewPlanningEnv)
    made.close()


def test_the_bve_as_a_policy_localises_the_fruit_and_says_so(env):
    """Seed 3 of the clean scene: the BVE's viewpoints, taken as actions, localise the fruit;
    the episode terminates (not truncates) with the outcome converged, the truth in info."""
    obs, info = env.reset(seed=3)
    assert obs["image"].shape == env.observation_space["image"].shape and obs["image"].any()
    prior_error = info["error_m"]
    rewards = []
    for _ in range(env.settings.episode.views):
        obs, reward, terminated, truncated, info = env.step(env.planner_action())
        rewards.append(reward)
        if terminated or truncated:
            break
    assert terminated and not truncated and info["outcome"] == "converged"
    assert info["error_m"] < 1e-3 < prior_error
    assert np.allclose(info["target"], env.unwrapped._target_m)
    assert rewards[0] > 0.0  # the first view after the start tells the filter something
    assert np.allclose(obs["belief_mean"][:3], env._running().belief.centre_m)


def test_a_view_that_moves_costs_what_it_moved_and_a_long_action_is_one_step(env):
    env.reset(seed=4)
    env.motion_cost = 1e6  # the cost dominates: reward ≈ -cost x steps moved
    before = env._running().world.p_world_camera
    _, reward, *_ = env.step(np.array([0.0, 5.0, 0.0], dtype=np.float32))  # scaled to length 1
    moved = np.linalg.norm(env._running().world.p_world_camera - before)
    assert moved <= env.settings.step_m * 1.05
    assert reward == pytest.approx(-1e6 * moved / env.settings.step_m, rel=1e-3)
    env.motion_cost = 0.1


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"scenario": "no_such_scene"}, "only"),
        ({"motion_cost": -1.0}, "motion_cost"),
        ({"render_mode": "human"}, "render_mode"),
    ],
)
def test_bad_construction_is_a_clear_error(kwargs, field):
    with pytest.raises(ConfigError, match=field):
        ViewPlanningEnv(**kwargs)


def test_bad_actions_and_a_step_before_reset_are_clear_errors(env):
    fresh = ViewPlanningEnv(scenario="clean")
    with pytest.raises(RuntimeError, match="reset"):
        fresh.step(np.zeros(3, dtype=np.float32))
    env.reset(seed=3)
    for bad in (np.zeros(2), np.array([np.nan, 0.0, 0.0])):
        with pytest.raises(ConfigError, match="action"):
            env.step(bad)
