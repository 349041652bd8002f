"""A view that shows a hidden fruit: positions ranked by the outline the tracks predict, within
the step and the task's constraints, and the every-fruit planner taking one in place of a BVE
view that would not see its fruit."""

import math

import numpy as np
import pytest

from bve_mj.estimation.belief import Belief
from bve_mj.estimation.visibility import outline_shown_deg, visible_arc_deg
from bve_mj.geometry import camera_rotation
from bve_mj.planning.constraints import DistanceBand, PlantWall
from bve_mj.planning.every_fruit import EveryFruitPlanner, FruitTarget
from bve_mj.planning.plan import ViewPlan
from bve_mj.planning.unhide import UnhideOptions, unhiding_positions

F, W, H = 466.0, 640, 480
MIN_ARC = 150.0
FRONT = np.array([0.40, 0.0, 0.30])
BACK = np.array([0.455, 0.0, 0.30])  # touching FRONT, straight behind it seen from the aisle
CENTRES, RADII = np.array([FRONT, BACK]), np.array([0.03, 0.03])


def _arc(centres, radii, p, R):
    return visible_arc_deg(centres, radii, p, R, F, W, H, rims=True)


def _outline(index, centres, radii, positions):
    return outline_shown_deg(index, centres, radii, positions, F, W, H, rims=True)


def _shown(p, index=1):
    return float(_arc(CENTRES, RADII, p, camera_rotation(p, CENTRES[index]))[index])


def _constraints(k_hat):
    return [DistanceBand(k_hat, 0.3, 0.08), PlantWall(k_hat, 0.1)]


def test_a_fruit_behind_its_neighbour_gets_positions_that_show_it_within_the_step():
    camera = BACK + np.array([-0.3, 0.0, 0.0])  # behind FRONT: the back fruit is hidden
    assert _shown(camera) < MIN_ARC
    step = 0.15
    ranked = unhiding_positions(
        1, CENTRES, RADII, camera, _constraints(BACK), step, 0.3, _outline, MIN_ARC, np.random.default_rng(1)
    )
    assert ranked
    for p, arc in ranked:
        assert np.linalg.norm(p - camera) <= step + 1e-9
        assert all(g.value(p) <= 1e-9 for g in _constraints(BACK))
        assert arc == pytest.approx(_shown(p))
    assert ranked[0][1] >= MIN_ARC
    assert [a for _, a in ranked] == sorted((a for _, a in ranked), reverse=True)


def test_where_no_position_within_a_step_shows_it_the_camera_walks_towards_the_side_that_does():
    camera = BACK + np.array([-0.3, 0.0, 0.0])
    step = 0.02  # too short to leave the front fruit's shadow
    rng = np.random.default_rng(2)
    ranked = unhiding_positions(
        1, CENTRES, RADII, camera, _constraints(BACK), step, 0.3, _outline, MIN_ARC, rng
    )
    assert ranked and all(a < MIN_ARC for _, a in ranked)
    # walking there view by view uncovers it within a few steps (a walk in no direction in
    # particular takes 5-20 steps of 2 cm here)
    for seed in range(6):
        rng, camera = np.random.default_rng(seed), BACK + np.array([-0.3, 0.0, 0.0])
        for _ in range(6):
            ranked = unhiding_positions(
                1, CENTRES, RADII, camera, _constraints(BACK), step, 0.3, _outline, MIN_ARC, rng
            )
            camera = ranked[0][0]
            if ranked[0][1] >= MIN_ARC:
                break
        assert _shown(camera) >= MIN_ARC, seed


def test_no_position_satisfies_the_constraints_gives_none_and_bad_input_is_refused():
    camera = BACK + np.array([-0.3, 0.0, 0.0])
    impossible = [DistanceBand(BACK, 2.0, 0.01)]  # 2 m from the fruit: never within a step
    rng = np.random.default_rng(3)
    assert unhiding_positions(1, CENTRES, RADII, camera, impossible, 0.1, 2.0, _outline, MIN_ARC, rng) == []
    with pytest.raises(ValueError, match="out of range"):
        unhiding_positions(2, CENTRES, RADII, camera, [], 0.1, 0.3, _outline, MIN_ARC, rng)
    with pytest.raises(ValueError, match="step_m"):
        unhiding_positions(1, CENTRES, RADII, camera, [], -0.1, 0.3, _outline, MIN_ARC, rng)
    with pytest.raises(ValueError, match="band_distance_m"):
        unhiding_positions(1, CENTRES, RADII, camera, [], 0.1, math.nan, _outline, MIN_ARC, rng)
    with pytest.raises(ValueError, match="min_arc_deg"):
        unhiding_positions(1, CENTRES, RADII, camera, [], 0.1, 0.3, _outline, 0.0, rng)
    with pytest.raises(ValueError, match="samples"):
        UnhideOptions(samples=0)
    with pytest.raises(ValueError, match="keep"):
        UnhideOptions(keep=True)


class _Fixed:
    def __init__(self, p):
        self.p = np.asarray(p, dtype=float)

    def plan(self, belief, p_world_camera, iteration):
        return ViewPlan(self.p, belief.centre_m, "optimal", True, 0.0)


def _target(i, centre, sigma):
    return FruitTarget(i, Belief(np.r_[centre, 0.03], np.diag([sigma**2] * 3 + [1e-6])), False, sigma)


def test_the_planner_takes_the_unhiding_view_only_where_the_bve_view_would_not_see_its_fruit():
    aisle = BACK + np.array([-0.3, 0.0, 0.0])  # the BVE's view: the back fruit hidden
    side = BACK + np.array([-0.2, 0.2, 0.0])
    calls = []

    def unhide(fruit, fruits, p, q):
        calls.append(fruit.id)
        return ViewPlan(side, fruit.belief.centre_m, "optimal", True, 0.0)

    def visible(centres, radii, p, R):
        return _arc(centres, radii, p, R) >= MIN_ARC

    fruits = [_target(0, FRONT, 0.0005), _target(1, BACK, 0.02)]
    planner = EveryFruitPlanner(lambda: _Fixed(aisle), lambda f, p, R: 1.0, visible, 1, None, unhide)
    plan, planned_for = planner.plan(fruits, aisle, 1)
    assert planned_for == 1 and calls == [1]
    assert np.allclose(plan.p_world_camera, side)
    assert planner.last_scores[0].kind == "unhide" and 1 in planner.last_scores[0].sees
    # a BVE view that sees its fruit is kept, and unhide is not asked
    calls.clear()
    planner = EveryFruitPlanner(lambda: _Fixed(side), lambda f, p, R: 1.0, visible, 1, None, unhide)
    plan, _ = planner.plan(fruits, aisle, 1)
    assert calls == [] and planner.last_scores[0].kind == "bve"
    # without unhide the hidden view is taken as before
    planner = EveryFruitPlanner(lambda: _Fixed(aisle), lambda f, p, R: 1.0, visible, 1)
    plan, _ = planner.plan(fruits, aisle, 1)
    assert np.allclose(plan.p_world_camera, aisle) and planner.last_scores[0].sees == (0,)


def test_the_arm_reaches_the_unhiding_view_looking_at_the_hidden_fruit():
    """With the Manipulator-H: the view returned is one the arm's joint angles realise (forward
    kinematics puts the camera there, looking at the fruit's estimate), within a step of the
    camera and the task's constraints, and it shows the fruit hidden from where the camera is."""
    from bve_mj.config import Settings
    from bve_mj.loop.mujoco import episode_constraints, episode_settings
    from bve_mj.loop.unhiding import ArmUnhider
    from bve_mj.planning.constraints import build_constraints
    from bve_mj.robot import IkOptions, arm_kinematics, look_at_ik

    s = episode_settings(Settings())
    kin = arm_kinematics(s.robot.name, s.robot.limit_set)
    front, back = np.array([0.42, 0.0, 0.25]), np.array([0.475, 0.0, 0.25])
    camera = back + np.array([-0.3, 0.0, 0.0])
    rng = np.random.default_rng(4)
    q = look_at_ik(kin, camera, back, None, rng, IkOptions(upright=True)).q
    fruits = [_target(0, front, 0.0005), _target(1, back, 0.02)]
    centres, radii = np.array([front, back]), np.array([0.03, 0.03])
    assert _arc(centres, radii, camera, camera_rotation(camera, back))[1] < MIN_ARC
    names = episode_constraints(s)
    unhide = ArmUnhider(s, names, kin, _outline, MIN_ARC, rng, True, q)
    plan = unhide(fruits[1], fruits, camera, q)
    assert plan is not None and plan.q is not None
    p, R = kin.camera_pose(plan.q)
    np.testing.assert_allclose(p, plan.p_world_camera, atol=1e-3)
    to_fruit = (back - p) / np.linalg.norm(back - p)
    assert float(R[:, 0] @ to_fruit) > math.cos(math.radians(0.5))  # looks at it
    assert np.linalg.norm(plan.p_world_camera - camera) <= s.step_m + 1e-9
    assert all(g.value(plan.p_world_camera) <= 1e-6 for g in build_constraints(names, s, back))
    assert _arc(centres, radii, p, R)[1] >= MIN_ARC
    with pytest.raises(ValueError, match="not among"):
        unhide(_target(7, back, 0.02), fruits, camera, q)
    for bad in (-1, 1.5, True):
        with pytest.raises(ValueError, match="ik_restarts"):
            ArmUnhider(s, names, kin, _outline, MIN_ARC, rng, True, q, ik_restarts=bad)


@pytest.mark.parametrize("bad", [1, "true", None])
def test_the_setting_is_validated_and_a_bad_value_is_exit_2_with_one_line(bad, tmp_path):
    import subprocess
    import sys

    from bve_mj.config import TrackingConfig
    from bve_mj.errors import ConfigError

    with pytest.raises(ConfigError, match=r"tracking\.unhide"):
        TrackingConfig(unhide=bad)
    if bad == "true":  # once through the command line: a scenario file that sets it so
        cfg = tmp_path / "bad.toml"
        cfg.write_text('[tracking]\nunhide = "true"\n')
        out = subprocess.run(
            [sys.executable, "-m", "bve_mj.cli", "episode", "--config", str(cfg), "--fruits", "all"],
            capture_output=True,
            text=True,
        )
        assert out.returncode == 2
        assert out.stderr.strip().count("\n") == 0 and "tracking.unhide" in out.stderr


def test_the_outline_of_many_cameras_at_once_is_the_outline_of_each():
    """:func:`outline_shown_deg` (every position at once, each camera looking at the fruit) gives
    exactly :func:`visible_arc_deg`'s number for each, with and without rims, looking straight
    down included; a camera inside the fruit sees none of it."""
    rng = np.random.default_rng(1)
    for _ in range(40):
        n = int(rng.integers(1, 9))
        centres = np.array([0.45, 0.0, 0.25]) + rng.normal(0.0, 0.04, (n, 3))
        radii = rng.uniform(0.01, 0.04, n)
        i = int(rng.integers(n))
        positions = centres[i] + rng.normal(0.0, 0.25, (12, 3))
        positions[0] = centres[i] + np.array([0.0, 0.0, 0.3])  # straight above
        for rims in (False, True):
            batch = outline_shown_deg(i, centres, radii, positions, F, W, H, rims=rims)
            one = [
                visible_arc_deg(centres, radii, p, camera_rotation(p, centres[i]), F, W, H, rims=rims)[i]
                for p in positions
            ]
            np.testing.assert_array_equal(batch, one)
    inside = outline_shown_deg(0, CENTRES, RADII, np.array([FRONT, FRONT + 0.01]), F, W, H)
    np.testing.assert_array_equal(inside, [0.0, 0.0])
    with pytest.raises(ValueError, match="out of range"):
        outline_shown_deg(2, CENTRES, RADII, np.array([FRONT]), F, W, H)


def test_the_loop_says_which_views_were_taken_to_show_a_hidden_fruit():
    """The every-fruit loop's event ``unhiding`` for a view whose chosen candidate was an
    unhiding view, none for a BVE view or a planner that keeps no scores."""
    from bve_mj.loop.every_fruit import _unhiding
    from bve_mj.planning.every_fruit import CandidateScore

    class Scored:
        last_scores = (
            CandidateScore(1, 2.0, (1,), "optimal", "unhide"),
            CandidateScore(0, 1.0, (0,), "optimal"),
        )

    assert [str(e) for e in _unhiding(Scored(), 1)] == ["unhiding: fruit 1"]
    assert _unhiding(Scored(), 0) == []
    assert _unhiding(object(), 1) == []  # type: ignore[arg-type]
