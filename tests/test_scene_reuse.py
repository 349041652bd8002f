"""Paired episodes share their scene: run ``i`` of every cell of a campaign draws the same
scene, and a process keeps the last compiled ones (:data:`bve_mj.loop.start.KEPT_SCENES`)
with their ready poses and render contexts. Sharing changes no result."""

from __future__ import annotations

import numpy as np
import pytest

from bve_mj import Settings
from bve_mj.config import with_overrides
from bve_mj.loop import start
from bve_mj.loop.mujoco import episode_settings, run_mujoco_episode
from bve_mj.robot import arm_kinematics
from bve_mj.sim.scene_model import Fruit


def _signature(episode) -> tuple:
    r = episode.result
    return (
        r.outcome,
        r.final.mean.tobytes(),
        r.final.cov.tobytes(),
        tuple(v.p_world_camera.tobytes() for v in r.views),
    )


def test_episodes_of_a_kept_scene_are_those_of_a_fresh_one():
    """The BVE and the random baseline on two seeds, interleaved as a worker runs a paired
    campaign: the same episodes, to the bit, as each built from scratch."""
    cells = [
        Settings(),
        with_overrides(Settings(), planner={"kind": "random"}, measurement={"kind": "range"}),
    ]
    fresh = {}
    for seed in (3, 4):
        for k, s in enumerate(cells):
            start.clear_kept_scenes()
            fresh[seed, k] = _signature(run_mujoco_episode(s, seed))
    start.clear_kept_scenes()
    for seed in (3, 4):
        for k, s in enumerate(cells):
            assert _signature(run_mujoco_episode(s, seed)) == fresh[seed, k], (seed, k)
    assert len(start._SCENES) == 2


def test_a_kept_scene_is_one_read_only_model_and_a_scripted_one_is_its_own():
    s = episode_settings(Settings())
    start.clear_kept_scenes()
    a, b = start.start_episode(s, 7), start.start_episode(s, 7)
    assert a.model is b.model and a.info is b.info
    assert np.array_equal(a.q_start, b.q_start) and a.q_start is not b.q_start
    with pytest.raises(ValueError, match="read-only"):
        a.info.target.centre_m[0] += 1.0
    other = start.start_episode(with_overrides(s, scene={"fruit_per_truss": 4}), 7)
    assert other.model is not a.model  # other scene settings: another scene
    t = a.info.target
    scripted = Fruit(t.name, t.centre_m.copy(), t.radius_m, t.colour)
    assert start.start_episode(s, 7, target=scripted).model is not a.model
    for k in range(start.KEPT_SCENES + 1):
        start.start_episode(s, 100 + k)
    assert len(start._SCENES) == start.KEPT_SCENES
    assert start.start_episode(s, 7).model is not a.model  # evicted: built again


def test_a_kept_ready_pose_leaves_the_generator_where_the_search_does():
    """The ready pose is remembered with the state its search leaves the prior's generator in
    (the detection prior draws from it next)."""
    s = episode_settings(Settings())
    kin = arm_kinematics(s.robot.name, s.robot.limit_set)
    estimate = np.array([0.42, 0.03, 0.31])
    start.clear_kept_scenes()
    searched = np.random.default_rng(11)
    q = start._start_configuration(
        kin, estimate, s.band_distance_m, searched, upright=s.planner.upright > 0.0
    )
    for _ in range(2):  # computed, then remembered
        rng = np.random.default_rng(11)
        assert np.array_equal(start._ready_pose(s, kin, estimate, rng), q)
        assert rng.bit_generator.state == searched.bit_generator.state
    assert len(start._READY) == 1
