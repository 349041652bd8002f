"""Every fruit of a truss: the planner's joint information, the harvest order, the command
line, and a seeded episode in the rendered greenhouse."""

import dataclasses
import json
import subprocess
import sys

import numpy as np
import pytest

from bve_mj.config import Settings, load_settings, with_overrides
from bve_mj.estimation import BearingSizeModel, Belief
from bve_mj.geometry import camera_rotation
from bve_mj.loop.fruit_records import FruitState
from bve_mj.loop.harvest import harvest_order
from bve_mj.planning.every_fruit import EveryFruitPlanner, FruitTarget, information_gain
from bve_mj.planning.plan import ViewPlan

F, W, H = 466.0, 640, 480


def test_information_gain_is_the_log_volume_the_centre_loses():
    rng = np.random.default_rng(3)
    A = rng.normal(size=(4, 4))
    P = A @ A.T * 1e-5 + np.eye(4) * 1e-6
    b = Belief(np.array([0.4, 0.0, 0.3, 0.03]), P)
    p = np.array([0.1, 0.05, 0.35])
    m = BearingSizeModel(p, camera_rotation(p, b.centre_m), np.eye(3) * 1e-6)
    Hm = m.jacobian(b.mean)
    # the Kalman update's posterior, the long way
    S = Hm @ P @ Hm.T + m.noise_cov
    K = P @ Hm.T @ np.linalg.inv(S)
    post = (np.eye(4) - K @ Hm) @ P
    expected = np.linalg.slogdet(P[:3, :3])[1] - np.linalg.slogdet(post[:3, :3])[1]
    assert information_gain(b, Hm, m.noise_cov) == pytest.approx(expected, rel=1e-9)
    assert information_gain(b, Hm, m.noise_cov * 1e6) < 1e-3 * expected


class _Fixed:
    """A single-fruit planner that proposes a fixed viewpoint."""

    def __init__(self, p):
        self.p = np.asarray(p, dtype=float)
        self.planned = 0

    def plan(self, belief, p_world_camera, iteration):
        self.planned += 1
        return ViewPlan(self.p, belief.centre_m, "optimal", True, 0.0)


def _target(i, centre, sigma, localised=False):
    return FruitTarget(i, Belief(np.r_[centre, 0.03], np.diag([sigma**2] * 3 + [1e-6])), localised, sigma)


def test_the_view_that_sees_more_open_fruit_wins_and_a_hidden_one_counts_nothing():
    a, b = np.array([0.5, 0.0, 0.3]), np.array([0.5, 0.08, 0.3])
    front = np.array([0.2, 0.04, 0.3])  # sees both
    behind_a = np.array([0.2, -0.12, 0.3])  # b hides behind a seen from here? no: far to the side
    views = iter([_Fixed(behind_a), _Fixed(front)])

    def gain(fruit, p, R):
        return 1.0  # every fruit seen gains the same

    def visible(centres, radii, p, R):
        return np.array([True, np.allclose(p, front)])  # fruit b only from the front view

    planner = EveryFruitPlanner(lambda: next(views), gain, visible, candidates=2)
    fruits = [_target(0, a, 0.01), _target(1, b, 0.005)]
    plan, planned_for = planner.plan(fruits, np.array([0.2, 0.0, 0.3]), 1)
    assert np.allclose(plan.p_world_camera, front)
    assert planned_for == 1
    assert [s.score for s in planner.last_scores] == [1.0, 2.0]
    # a localised fruit is no candidate and gains nothing
    fruits = [_target(0, a, 0.01), _target(1, b, 0.0005, localised=True)]
    planner.plan(fruits, np.array([0.2, 0.0, 0.3]), 2)
    assert [s.planned_for for s in planner.last_scores] == [0]
    assert planner.last_scores[0].score == 1.0
    with pytest.raises(Exception, match="every fruit is localised"):
        planner.plan([_target(0, a, 0.0005, localised=True)], np.zeros(3), 3)


def test_a_view_from_where_a_fruit_was_hidden_counts_less_of_its_gain_until_one_measures_it():
    """Two candidate views, each predicted to see both fruit (1 nat each): they tie, the first
    wins. A view from the first one's direction was predicted to show fruit 1 and did not
    measure it (a stem the tracks do not hold): from there fruit 1 counts nothing, 13° off
    half, and the second view wins; once a view measures fruit 1 (or its track is gone) the
    views tie again."""
    a, b = np.array([0.5, 0.0, 0.3]), np.array([0.5, 0.08, 0.3])
    first, second = np.array([0.2, 0.0, 0.3]), np.array([0.3, 0.3, 0.3])  # 55° apart seen from b
    views = iter([_Fixed(first), _Fixed(second)])
    planner = EveryFruitPlanner(lambda: next(views), lambda f, p, R: 1.0,
                                lambda c, r, p, R: np.ones(len(c), dtype=bool), candidates=2)  # fmt: skip
    fruits = [_target(0, a, 0.01), _target(1, b, 0.01)]

    def chosen():
        plan, _ = planner.plan(fruits, np.array([0.2, 0.04, 0.3]), 1)
        return [s.score for s in planner.last_scores], plan.p_world_camera

    scores, at = chosen()
    assert scores == [2.0, 2.0] and np.allclose(at, first)
    planner.note_hidden(1, first + 0.1 * (first - b) / np.linalg.norm(first - b), b)
    scores, at = chosen()
    assert scores == pytest.approx([1.0, 2.0], abs=1e-6) and np.allclose(at, second)
    assert planner._shown(1, b + rotation_about_z(13.0) @ (first - b), b) == pytest.approx(0.5, abs=0.03)
    planner.note_fused_view(1, second, b)
    assert chosen()[0] == [2.0, 2.0]
    planner.note_hidden(1, first, b)
    planner.forget(1)
    assert planner._shown(1, first, b) == 1.0


def rotation_about_z(deg):
    t = np.radians(deg)
    return np.array([[np.cos(t), -np.sin(t), 0.0], [np.sin(t), np.cos(t), 0.0], [0.0, 0.0, 1.0]])


def test_a_view_whose_move_is_not_clear_is_left_out_and_with_none_clear_the_planner_fails():
    """The world's clearance check (``clear``): the better view's move passes through a known
    fruit, so the other candidate's view is taken; with no clear move the planner raises
    (the loop then holds the camera), and an exploring view likewise."""
    from bve_mj.errors import BveError

    a, b = np.array([0.5, 0.0, 0.3]), np.array([0.5, 0.08, 0.3])
    front, side = np.array([0.2, 0.04, 0.3]), np.array([0.2, -0.12, 0.3])

    def visible(centres, radii, p, R):
        return np.array([True, np.allclose(p, front)])  # the front view sees both: it is better

    def make_planner(clear):
        views = iter([_Fixed(side), _Fixed(front), _Fixed(front)])
        return EveryFruitPlanner(lambda: next(views), lambda f, p, R: 1.0, visible, 2, clear)

    fruits = [_target(0, a, 0.01), _target(1, b, 0.005)]
    plan, _ = make_planner(lambda plan: True).plan(fruits, np.array([0.2, 0.0, 0.3]), 1)
    assert np.allclose(plan.p_world_camera, front)
    planner = make_planner(lambda plan: not np.allclose(plan.p_world_camera, front))
    plan, planned_for = planner.plan(fruits, np.array([0.2, 0.0, 0.3]), 1)
    assert np.allclose(plan.p_world_camera, side) and planned_for == 0
    assert [s.planned_for for s in planner.last_scores] == [0]
    blocked = make_planner(lambda plan: False)
    with pytest.raises(BveError, match="passes through a known fruit"):
        blocked.plan(fruits, np.array([0.2, 0.0, 0.3]), 1)
    zone = Belief(np.r_[a, 0.03], np.eye(4) * 1e-4)
    with pytest.raises(BveError, match="exploration view passes through"):
        blocked.explore(zone, np.array([0.2, 0.0, 0.3]), 2)


def _state(i, centre, radius=0.03):
    return FruitState(i, Belief(np.r_[centre, radius], np.eye(4) * 1e-8), True, 3, 0, 3, True)


def test_the_harvest_order_takes_the_exposed_fruit_before_the_hidden_then_the_nearest():
    camera = np.array([0.1, 0.0, 0.3])
    front = _state(0, [0.40, 0.0, 0.3])
    behind = _state(1, [0.46, 0.01, 0.3])  # hidden behind `front` from the camera's side
    far_side = _state(2, [0.45, 0.2, 0.3])  # alone, exposed, farther than `front`
    order = harvest_order([behind, far_side, front], camera, F, W, H)
    # the lone fruit shows its whole outline, the one in front loses where the one behind it
    # touches it in the image (red on red), the one behind is hidden
    assert order == [2, 0, 1]
    # two fruit equally exposed: the nearest first
    near, far = _state(3, [0.40, -0.2, 0.3]), _state(4, [0.55, 0.2, 0.3])
    assert harvest_order([far, near], camera, F, W, H) == [3, 4]


def _cli(*args):
    return subprocess.run(
        [sys.executable, "-m", "bve_mj.cli", *args], capture_output=True, text=True, timeout=120
    )


@pytest.mark.parametrize(
    "args, field",
    [
        (["episode", "--fruits", "some"], "fruits"),
        (["scenarios", "--fruits", "every"], "fruits"),
        (["episode", "--fruits", "all", "--measurement", "range"], "tracking.fruits"),
        (["scenarios", "--fruits", "all", "--measurement", "range"], "measurement"),
        (["scenarios", "--planners", "bve,circle"], "planners"),
        (["scenarios", "--fruits", "all", "--planners", "bve,orbit"], "planners"),
        (["scenarios", "--fruits", "all", "--planners", "bve,bve"], "planners"),
        (["episode", "--fruits", "all", "--planner", "spiral"], "planner"),
        (["episode", "--pick", "2"], "pick"),
        (["episode", "--fruits", "all", "--pick", "11"], "pick"),
        (["episode", "--fruits", "all", "--pick", "some"], "pick"),
        (["scenarios", "--pick", "2"], "pick"),
        (["scenarios", "--fruits", "all", "--pick", "-1"], "pick"),
    ],
)
def test_bad_fruits_input_exits_2_with_one_line(args, field):
    r = _cli(*args)
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and field in lines[0], r.stderr


def _row(run, views_to_truss, outcome="converged"):
    fruit = {
        "error_mm": 1.0,
        "nees": 2.0,
        "localised": True,
        "outside_claim": False,
        "within": True,
        "radius_error_mm": 0.1,
    }
    return {
        "run": run, "outcome": outcome, "views": 10, "views_to_truss": views_to_truss, "fruits": [fruit],
        "false_tracks": 0, "plan_ms": [1.0], "track_ms": [1.0], "tracks_max": 1, "wall_s": 1.0,
    }  # fmt: skip


def test_planners_are_compared_on_the_same_seeds_never_counting_as_more_views_than_any():
    """Paired by run: BVE fewer on runs 0, 1 (the baseline never got there on 1), as many on
    run 2 (both never), more on run 3; the median counts never as infinitely many."""
    from types import SimpleNamespace

    from bve_mj.campaigns.fruit_suite import FruitSuiteResult, compare_fruit_planners

    sc = (SimpleNamespace(name="truss"),)
    bve = FruitSuiteResult(sc, {"truss": (_row(0, 5), _row(1, 6), _row(2, None), _row(3, 9))}, 0, 4, 1.0)
    fixed = FruitSuiteResult(sc, {"truss": (_row(0, 7), _row(1, None), _row(2, None), _row(3, 8))}, 0, 4, 1.0)
    assert bve.summary("truss")["views_to_truss_median"] == 7.5
    assert fixed.summary("truss")["views_to_truss_median"] == float("inf")
    assert fixed.summary("truss")["truss_pct"] == 50.0
    lines = compare_fruit_planners({"bve": bve, "fixed": fixed})
    row = next(line for line in lines if line.split()[:2] == ["truss", "fixed"])
    assert "2/1/1" in row.replace(" ", ""), row
    with pytest.raises(Exception, match="planners"):
        compare_fruit_planners({"fixed": fixed})


def test_a_baseline_aims_at_the_fruit_found_and_plans_for_none_of_them():
    from bve_mj.planning.every_fruit import EXPLORE
    from bve_mj.planning.fruit_baselines import PatternPlanner

    seen = []

    class Record:
        def plan(self, belief, p_world_camera, iteration):
            seen.append(belief.centre_m.copy())
            return ViewPlan(p_world_camera + 0.01, belief.centre_m, "optimal", True, 0.0)

    zone = Belief(np.array([0.5, 0.0, 0.4, 0.03]), np.diag([0.01, 0.01, 0.01, 1e-6]))
    pattern = PatternPlanner(Record(), zone)
    camera = np.array([0.2, 0.0, 0.4])
    _, planned_for = pattern.plan([], camera, 1)
    assert planned_for == EXPLORE and np.allclose(seen[-1], zone.centre_m)
    fruits = [
        FruitTarget(i, Belief(np.array([0.5, y, 0.4, 0.03]), 1e-6 * np.eye(4)), False, 1e-3)
        for i, y in enumerate((-0.02, 0.04))
    ]
    pattern.plan(fruits, camera, 2)
    assert np.allclose(seen[-1], [0.5, 0.01, 0.4])
    pattern.explore(zone, camera, 3)  # exploring keeps the aim at the fruit
    assert np.allclose(seen[-1], [0.5, 0.01, 0.4])


def test_a_tracking_section_is_validated():
    with pytest.raises(Exception, match=r"tracking\.zone_m"):
        with_overrides(Settings(), tracking={"zone_m": -1.0})
    with pytest.raises(Exception, match=r"tracking\.zone_m"):
        with_overrides(Settings(), tracking={"zone_m": 2.0})
    with pytest.raises(Exception, match=r"tracking\.gate_probability"):
        with_overrides(Settings(), tracking={"gate_probability": 1.0})


def test_a_ripe_truss_of_six_is_localised_and_every_fruit_visited_without_touching_any():
    """`bve-mj episode --fruits all --approach` on a truss of six ripe fruit (the suite's
    ripe_truss with a work zone holding all six). This seed localises 6 of 6 and visits each;
    not every seed does: over the ten seeds ``episode_seed(2026, 0-9)`` 49 of 60 fruit are
    localised within 5 mm and one episode leaves visits unreached ("every reachable pose's
    path passes too close to a fruit"; before the detector used interior edges, also 49 of
    60, unreached visits in three). The seed written first, 1216546553, now localises 5 and
    cannot reach two of them clear of the others."""
    from bve_mj.campaigns.scenarios import suite_dir
    from bve_mj.loop.mujoco_fruits import run_every_fruit_episode

    s = load_settings(suite_dir() / "ripe_truss.toml")
    s = with_overrides(s, tracking={"fruits": "all", "zone_m": 0.25}, episode={"approach": True})
    ep = run_every_fruit_episode(s, 479243620)
    matches, _, false = ep.matches()
    assert len(matches) == 6
    assert sum(m.localised_within(5.0) for m in matches) >= 5
    assert false == []
    # the fruit localised after the first k views: none after the start's alone (a track is
    # localised after 3 hits), as many as the final tracks hold after every view, all six at
    # the view that localised the whole truss and not before it
    views = len(ep.result.views)
    assert ep.localised_after(1, 5.0) == 0
    assert ep.localised_after(views, 5.0) == ep.localised_after(10 * views, 5.0)
    assert ep.localised_after(views, 5.0) == sum(m.localised_within(5.0) for m in matches)
    k = ep.views_to_localise(5.0)
    if k is not None:
        assert ep.localised_after(k, 5.0) == 6 and ep.localised_after(k - 1, 5.0) < 6
    with pytest.raises(ValueError, match="at least 1"):
        ep.localised_after(0, 5.0)
    assert ep.harvest is not None and len(ep.harvest.visits) == len(
        [t for t in ep.result.final if t.localised]
    )
    for v in ep.harvest.visits:
        assert v.reached and v.distance_m <= ep.settings.episode.approach_distance_m + 0.01
        assert v.clearance_m > 0.0, f"the arm touched a fruit visiting track {v.track}"
    doc = ep.to_json()
    json.dumps(doc)  # JSON-ready
    assert {
        "truth_m",
        "radius_mm",
        "estimate_m",
        "radius_estimate_mm",
        "error_mm",
        "nees",
        "localised",
    } <= set(doc["fruits"][0])
    assert "unmatched_tracks" in doc


def test_a_cluster_whose_back_fruit_are_never_measured_is_not_called_complete():
    """`truss_cluster`, seed 1745651037: the two ripe fruit behind the front ones show only
    short arcs from every view the arm reaches, and are never measured. Before fruit seen in
    part were tracked, the episode ended `converged` (every fruit found) in 5 views with 2 of
    4 ripe fruit missing. Now it reports the fruit seen in part (each, at the end, near a
    missing fruit: its position is rough, its σ the filter's of weak sightings, not
    calibrated; early on one may lie between fruit, formed of arcs of several), plans views
    for them, and does not say it found every fruit."""
    from bve_mj.campaigns.scenarios import suite_dir
    from bve_mj.loop.every_fruit import seen_in_part_key
    from bve_mj.loop.mujoco_fruits import run_every_fruit_episode
    from bve_mj.loop.outcomes import Outcome

    s = with_overrides(load_settings(suite_dir() / "truss_cluster.toml"), tracking={"fruits": "all"})
    ep = run_every_fruit_episode(s, 1745651037)
    matches, _, _ = ep.matches()
    missing = [m.fruit for m in matches if not m.localised_within(5.0)]
    assert missing and ep.result.outcome != Outcome.CONVERGED
    assert any(v.unmeasured for v in ep.result.views)
    seen = ep.result.unmeasured  # the fruit seen in part the episode reports
    assert seen
    for h in seen:  # each lies near a missing fruit: within its 3σ and a fruit's radius
        d, r = min((float(np.linalg.norm(h.belief.centre_m - f.centre_m)), f.radius_m) for f in missing)
        assert d < 3.0 * h.belief.sigma_max_m + r, (1e3 * d, 1e3 * h.belief.sigma_max_m)
    assert any(v.planned_for is not None and v.planned_for <= seen_in_part_key(0) for v in ep.result.views)
    doc = ep.to_json()
    assert len(doc["seen_in_part"]) == len(ep.result.unmeasured)


def test_a_visit_path_is_checked_against_every_track_sphere_on_the_way_not_only_at_its_ends():
    """The arm's geoms along the joint-space path: a sphere the wrist sweeps through halfway
    is found though both ends are clear of it; far away it is not."""
    import mujoco

    from bve_mj.sim.arm import CAMERA_NAME
    from bve_mj.sim.arm_boxes import path_clearance

    world, q0 = _arm_world()
    m, data, adr = world.model, world.data, world.qpos_adr
    q1 = q0.copy()
    q1[0] += 0.6  # swing the base: the wrist sweeps an arc
    data.qpos[adr] = q0 + 0.5 * (q1 - q0)
    mujoco.mj_kinematics(m, data)
    mujoco.mj_camlight(m, data)
    halfway = data.cam_xpos[m.camera(CAMERA_NAME).id].copy()
    data.qpos[adr] = q0
    qpos = data.qpos.copy()
    sphere = np.array([[*halfway, 0.02]])
    assert path_clearance(world, q0, q1, sphere) < 0.0
    assert path_clearance(world, q0, q0, sphere) > 0.0 and path_clearance(world, q1, q1, sphere) > 0.0
    far = np.array([[*(halfway + [0.0, 0.0, 2.0]), 0.02]])
    assert path_clearance(world, q0, q1, far) > 1.0
    # the arm is posed in a scratch MjData kept per model: the world's own is left alone,
    # and an answer is the same after other moves were measured as it was the first time
    first = path_clearance(world, q0, q1, sphere)
    path_clearance(world, q1, q1 + 0.3, far, 0.1, hand=False)
    assert path_clearance(world, q0, q1, sphere) == first
    np.testing.assert_array_equal(data.qpos, qpos)


def test_the_arm_boxes_are_made_once_per_world_and_go_with_it():
    """The arm's boxes and scratch ``MjData`` are kept for a world while it lives, not after
    (held by the model, the scratch data's reference to it kept every episode's alive)."""
    import gc
    import weakref

    from bve_mj.sim import arm_boxes

    ns, q0 = _arm_world()

    class World:  # the world as path_clearance reads it, one that can be weakly referenced
        def __init__(self) -> None:
            self.model, self.data, self.kin, self.qpos_adr = ns.model, ns.data, ns.kin, ns.qpos_adr

    world = World()
    boxes = arm_boxes._ArmBoxes.of(world)
    assert arm_boxes._ArmBoxes.of(world) is boxes
    assert arm_boxes.path_clearance(world, q0, q0 + 0.2, np.zeros((0, 4)), 10.0) > 0.0
    scratch = weakref.ref(boxes.scratch)  # (other tests' worlds may come and go meanwhile)
    del world, boxes
    gc.collect()
    assert scratch() is None  # the model (held here by ns) did not keep them


def _arm_world(seed: int = 1):  # the arm in its start scene, as path_clearance reads a world
    from types import SimpleNamespace

    import mujoco

    from bve_mj.loop.mujoco import episode_settings
    from bve_mj.loop.start import start_episode

    start = start_episode(episode_settings(Settings()), seed)
    m, kin = start.model, start.kin
    data = mujoco.MjData(m)
    adr = np.array([m.jnt_qposadr[m.joint(n).id] for n in kin.joint_names])
    return SimpleNamespace(model=m, data=data, kin=kin, qpos_adr=adr), start.q_start


def _deepest_x(world, q, hand: bool) -> float:
    """The farthest x of the hand's geoms (the last joint's link), or of the rest of the arm's."""
    import mujoco

    from bve_mj.sim.arm_boxes import _box_max_x, arm_geoms

    world.data.qpos[world.qpos_adr] = q
    mujoco.mj_kinematics(world.model, world.data)
    m, names = world.model, world.kin.joint_names
    ends = set(arm_geoms(m, names[-1:]))
    return max(_box_max_x(m, world.data, g) for g in arm_geoms(m, names) if (g in ends) == hand)


def test_the_canopy_keeps_the_arm_in_front_and_lets_only_the_hand_in():
    """The canopy's front (a plane across the row) is an obstacle: a plane ahead of the arm
    leaves it clear by the gap; a move that reaches through it is refused; with
    ``hand=False`` (the approach) the last link (flange and camera) may enter it, the rest
    of the arm may not; a move that starts behind the plane (the last view's pose) may come
    out, or stay, but not go deeper."""
    from bve_mj.sim.arm_boxes import path_clearance

    world, q0 = _arm_world()
    none = np.zeros((0, 4))
    q1 = q0.copy()
    q1[1] += 0.25  # the shoulder reaches forward: the hand 5 cm or more farther along x
    hand0, hand1 = _deepest_x(world, q0, True), _deepest_x(world, q1, True)
    rest1 = _deepest_x(world, q1, False)
    assert hand1 > hand0 + 0.05 and hand1 > rest1
    assert path_clearance(world, q0, q1, none, hand1 + 0.2) == pytest.approx(0.2, abs=0.01)
    assert path_clearance(world, q0, q1, none, hand1 - 0.01) == pytest.approx(-0.01, abs=1e-3)
    between = 0.5 * (max(hand0, rest1) + hand1)  # only the reaching hand crosses it
    assert path_clearance(world, q0, q1, none, between) < 0.0
    assert path_clearance(world, q0, q1, none, between, hand=False) > 0.0
    assert path_clearance(world, q0, q1, none, rest1 - 0.01, hand=False) < 0.0  # the wrist is in too
    assert path_clearance(world, q1, q0, none, between) == pytest.approx(0.0, abs=1e-12)  # coming out
    assert path_clearance(world, q1, q1, none, between) == pytest.approx(0.0, abs=1e-12)  # not deeper
    q2 = q1.copy()
    q2[1] += 0.1  # deeper still
    assert path_clearance(world, q1, q2, none, between) < 0.0


def test_a_move_leaving_a_sphere_the_arm_is_in_is_measured_against_the_others_only():
    """``leaving`` (a retreat's check): a geom inside a sphere at the start is not measured
    against it, so a move that takes it deeper there but nowhere else passes; a sphere the
    arm starts clear of still counts."""
    from bve_mj.sim.arm_boxes import path_clearance

    world, q0 = _arm_world()
    p0, R0 = world.kin.camera_pose(q0)
    q1 = q0.copy()
    q1[1] += 0.05  # the hand a little forward
    tangled = np.array([[*(p0 + 0.01 * R0[:, 0]), 0.03]])  # the camera starts inside it
    assert path_clearance(world, q0, q1, tangled) < 0.0  # deeper: refused
    leaving = path_clearance(world, q0, q1, tangled, leaving=True)  # the geoms outside it only
    assert leaving > 0.0
    ahead = np.array([[*(p0 + 0.2 * R0[:, 0]), 0.03]])  # ahead, clear of the move
    both = np.vstack([tangled, ahead])
    clear_ahead = path_clearance(world, q0, q1, ahead)
    assert clear_ahead > 0.0
    assert path_clearance(world, q0, q1, both, leaving=True) == pytest.approx(min(leaving, clear_ahead))
    q2 = q0.copy()
    q2[1] += 0.25  # the hand 5 cm or more forward
    p2, _ = world.kin.camera_pose(q2)
    into = np.array([[*p2, 0.015]])  # where the camera goes, clear of the arm at the start
    assert path_clearance(world, q0, q0, into) > 0.0
    assert path_clearance(world, q0, q2, np.vstack([tangled, into]), leaving=True) < 0.0  # still counts


def test_a_one_target_move_into_the_fruit_it_localises_is_refused_and_the_loop_holds():
    """The one-target loop's planner (:class:`ClearMovesPlanner`): a plan whose move brings
    the hand into the fruit the belief localises raises (the loop then holds the camera);
    the same move with the fruit 10 cm beyond the hand passes; a fruit known only loosely
    (σ 5 cm) is no obstacle while searching, but in approach mode the canopy stands 3σ
    nearer from the start (where its untracked neighbours may hang) and only the hand may
    enter it; a plan without joint angles passes unchecked; what the loop tells the planner
    reaches the one inside, and a planner that learns from failed views is told the blocked
    one (else it plans the same blocked move again from the same belief)."""
    import mujoco

    from bve_mj.errors import PlanningError
    from bve_mj.loop.arm_clearance import ClearMovesPlanner
    from bve_mj.sim.arm import CAMERA_NAME

    world, q0 = _arm_world()
    world.q = q0
    q1 = q0.copy()
    q1[1] += 0.25  # the hand reaches 5 cm or more farther along x
    hand1 = _deepest_x(world, q1, True)
    world.data.qpos[world.qpos_adr] = q1
    mujoco.mj_kinematics(world.model, world.data)
    mujoco.mj_camlight(world.model, world.data)
    reached = world.data.cam_xpos[world.model.camera(CAMERA_NAME).id].copy()  # the camera at q1

    class Inner:
        q = None

        def __init__(self, q=q1):
            self.plan_q = q

        def plan(self, belief, p_world_camera, iteration):
            return ViewPlan(reached, belief.centre_m, "optimal", True, 0.0, q=self.plan_q)

        def set_configuration(self, q):
            self.q = q

    class Learning(Inner):
        def __init__(self):
            super().__init__()
            self.failed = []

        def note_failed_view(self, p_world_camera, p_world_target):
            self.failed.append((p_world_camera.copy(), p_world_target.copy()))

    def fruit_at(dx, sigma=0.001):
        centre = np.array([hand1 + dx, reached[1], reached[2]])
        return Belief(np.r_[centre, 0.03], np.diag([sigma**2] * 3 + [1e-6]))

    planner = ClearMovesPlanner(Inner(), world, 0.03)
    with pytest.raises(PlanningError, match="into the fruit or the canopy"):
        planner.plan(fruit_at(0.02), np.zeros(3), 3)
    assert planner.plan(fruit_at(0.1), np.zeros(3), 3).q is q1
    assert planner.plan(fruit_at(0.1, sigma=0.05), np.zeros(3), 3).q is q1
    approach = ClearMovesPlanner(Inner(), world, 0.03, approach=True)
    assert approach.plan(fruit_at(0.1), np.zeros(3), 3).q is q1
    with pytest.raises(PlanningError):  # the canopy 21 cm nearer: the wrist in it too
        approach.plan(fruit_at(0.1, sigma=0.05), np.zeros(3), 3)
    assert ClearMovesPlanner(Inner(None), world, 0.03).plan(fruit_at(0.02), np.zeros(3), 3).q is None
    planner.set_configuration(q0)
    assert planner.planner.q is q0
    learning = ClearMovesPlanner(Learning(), world, 0.03)
    with pytest.raises(PlanningError):
        learning.plan(fruit_at(0.02), np.zeros(3), 3)
    ((camera, target),) = learning.planner.failed  # the blocked view, to plan elsewhere next
    np.testing.assert_allclose(camera, reached)
    np.testing.assert_allclose(target, fruit_at(0.02).centre_m)
    learning.plan(fruit_at(0.1), np.zeros(3), 3)
    assert len(learning.planner.failed) == 1  # a clear move is no failure


def test_baselines_take_only_views_whose_moves_keep_clear():
    """The baselines' clearance (:class:`BaselineClearance`): ``clear`` holds for a camera
    point the arm reaches by a clear move, fails where the camera would sit inside a known
    fruit and where no pose reaches; a random baseline with it chooses only points reached
    clear of a canopy 5 mm in front of the arm, and its plans carry the pose checked (the
    camera there); without it the same baseline moves into the canopy."""
    from bve_mj.config.experiments import EXPERIMENTS
    from bve_mj.loop.arm_clearance import BaselineClearance, Obstacles
    from bve_mj.robot import make_arm_planner
    from bve_mj.sim.arm_boxes import deepest_x, path_clearance

    world, q0 = _arm_world()
    world.q = q0
    p0, R0 = world.kin.camera_pose(q0)
    s = with_overrides(Settings(), planner={"kind": "random"})
    k_hat = p0 + s.band_distance_m * R0[:, 0]
    none = Obstacles((), np.zeros((0, 4)), np.inf)
    known = [none]
    check = BaselineClearance(world, lambda: known[0], upright=False)
    clear = check.constraints(k_hat)[0]
    c = p0 + 0.03 * R0[:, 0]  # 3 cm forward along the optical axis
    assert clear.value(c) < 0.0
    plan = check.posed(ViewPlan(c, k_hat, "optimal", True, 0.0))
    np.testing.assert_allclose(world.kin.camera_pose(plan.q)[0], c, atol=1e-4)
    known[0] = Obstacles((0,), np.array([[*(p0 + 0.04 * R0[:, 0]), 0.02]]), np.inf)  # 2 cm ahead now
    assert clear.value(c) > 0.0
    assert clear.value(p0 + np.array([2.0, 0.0, 0.0])) == 1.0  # out of reach
    front = deepest_x(world, q0) + 0.005
    known[0] = Obstacles((), np.zeros((0, 4)), front)

    def plans(checks) -> list[ViewPlan]:
        baseline = make_arm_planner(s, EXPERIMENTS["E5"].loss, ["band"], world.kin, q0,
                                    np.random.default_rng(3), checks)  # fmt: skip
        planner = check.planner(baseline) if checks is not None else baseline
        return [planner.plan(Belief.isotropic(k_hat, 0.005), p0, i) for i in range(12)]

    checked = plans(check.constraints)
    assert all(p.q is not None for p in checked)
    for p in checked:
        np.testing.assert_allclose(world.kin.camera_pose(p.q)[0], p.p_world_camera, atol=1e-4)
        assert path_clearance(world, q0, p.q, np.zeros((0, 4)), front) >= 0.0
    # the control: unchecked, some of the same baseline's points take the arm into the canopy
    unchecked = [p.p_world_camera for p in plans(None)]
    assert any(clear.value(c) > 0.0 for c in unchecked)


def test_the_obstacles_are_every_confirmed_track_and_fruit_seen_in_part_and_the_canopy_before_them():
    """A harvest keeps clear of what it knows: each sphere is a fruit's estimate with its
    radius plus 3σmax, fruit seen in part included, those known to less than their radius
    left out (the canopy stands for them), and the canopy's front lies the margin
    in front of the known fruit's median front; the visited fruit is left out of the
    spheres its own visit pose is checked against."""
    from bve_mj.loop.arm_clearance import CANOPY_MARGIN_M, Obstacles

    def state(i: int, centre, radius: float, sigma: float) -> FruitState:
        b = Belief(np.r_[centre, radius], np.diag([sigma**2] * 3 + [1e-8]))
        return FruitState(i, b, True, 3, 0, 3, True)

    tracks = [state(0, [0.42, 0.0, 0.2], 0.03, 0.001), state(1, [0.40, 0.05, 0.2], 0.025, 0.002)]
    part = [state(0, [0.38, -0.05, 0.15], 0.02, 0.006)]
    known = Obstacles.of(tracks, part)
    assert known.ids == (0, 1, -1)
    np.testing.assert_allclose(known.spheres[:, 3], [0.033, 0.031, 0.038], atol=1e-9)
    assert known.canopy_x_m == pytest.approx(0.375 - CANOPY_MARGIN_M)  # the median front
    # one fruit ranged far in front of the truss (a false or mis-sized track) does not move it
    stray = Obstacles.of([*tracks, state(2, [0.25, 0.0, 0.2], 0.02, 0.001)], part)
    assert stray.canopy_x_m == pytest.approx(0.3675 - CANOPY_MARGIN_M)
    np.testing.assert_allclose(known.without(0)[:, :3], [[0.40, 0.05, 0.2], [0.38, -0.05, 0.15]])
    assert Obstacles.of([]).canopy_x_m == np.inf and Obstacles.of([]).spheres.shape == (0, 4)
    loose = state(3, [0.30, 0.0, 0.2], 0.03, 0.011)  # 3σ 33 mm > its radius: not an obstacle
    assert Obstacles.of([*tracks, loose]).ids == (0, 1)


def test_a_harvest_that_swept_through_an_unseen_truss_now_approaches_from_the_aisle():
    """`ripe_truss`, the suite's episode 8 of seed 4242: before visits approached along a
    line and kept out of the canopy, the wrist swept through the truss above (fruit it never
    saw: no track) on two visits, 17 and 9 mm into them. Every visit now reaches its pose
    and the arm keeps clear of every true fruit."""
    from bve_mj.campaigns.scenarios import load_suite
    from bve_mj.campaigns.spec import episode_seed
    from bve_mj.loop.mujoco_fruits import run_every_fruit_episode

    (sc,) = load_suite(only=["ripe_truss"])
    s = with_overrides(
        sc.settings("camera", None, "centre_radius"), tracking={"fruits": "all"}, episode={"approach": True}
    )
    ep = run_every_fruit_episode(s, episode_seed(4242, 8))
    assert ep.harvest is not None and len(ep.harvest.visits) >= 4
    for v in ep.harvest.visits:
        assert v.reached, v.reason
        assert v.clearance_m > 0.0, f"the arm touched a fruit visiting track {v.track}"


def test_the_places_behind_the_front_row_keep_an_episode_from_saying_it_found_every_fruit():
    """`truss_cluster` 428971644: every view from the aisle, below the truss; the two ripe fruit
    behind the front row never measured. Counting a place framed once in an image, the zone
    check calls the whole zone framed (the episode ended ``converged`` with the packages of
    2026-12-07; with mujoco 4.0.1 / numpy 2.4.6 a track left open ends it ``max_views``);
    with ``tracking.zone_behind_fruit`` the places where a neighbour of the known fruit would
    sit must have been shown past them: the zone is not framed and the episode does not say
    it found every fruit."""
    from bve_mj.campaigns.scenarios import suite_dir
    from bve_mj.loop.mujoco_fruits import run_every_fruit_episode
    from bve_mj.loop.outcomes import Outcome

    s = with_overrides(load_settings(suite_dir() / "truss_cluster.toml"), tracking={"fruits": "all"})
    loose = run_every_fruit_episode(s, 428971644)
    matches, _, _ = loose.matches()
    assert sum(not m.localised_within(5.0) for m in matches) == 2
    assert loose.result.views[-1].zone_framed == 1.0  # the wrong belief the option is for
    strict = run_every_fruit_episode(with_overrides(s, tracking={"zone_behind_fruit": True}), 428971644)
    assert strict.result.outcome != Outcome.CONVERGED
    assert strict.result.views[-1].zone_framed < 1.0


def test_the_views_keep_the_arm_off_the_fruit_the_robot_knows():
    """`cherry_truss`, the suite's episode 0 of seed 9494: a false track ranged 30 cm behind
    the row drew the views towards it (`restoring`), end link and wrist 5-20 mm into six
    cherries of the truss. Each view's move is now checked against the fruit tracked and
    seen in part and the canopy: the arm keeps clear of every true fruit."""
    from bve_mj.campaigns.scenarios import load_suite
    from bve_mj.campaigns.spec import episode_seed
    from bve_mj.loop.arm_clearance import FruitClearance
    from bve_mj.loop.mujoco_fruits import run_every_fruit_episode

    class Clearance:  # an episode recorder that only measures
        def attach(self, world, ripe, zone_centre_m):
            self.clearance = FruitClearance(world, world.info)

        def on_step(self, sim_time):
            self.clearance.step(sim_time)

        def on_view(self, view):
            pass

    (sc,) = load_suite(only=["cherry_truss"])
    s = with_overrides(sc.settings("camera", None, "centre_radius"), tracking={"fruits": "all"})
    recorder = Clearance()
    ep = run_every_fruit_episode(s, episode_seed(9494, 0), recorder)
    assert len(ep.result.views) >= 6  # 7 since fits to 1 px are measured (8 before): moves to check
    least = recorder.clearance.least_m
    assert least > 0.0, f"the arm reached {-1e3 * least:.1f} mm into a fruit"


def test_a_claimed_track_keeps_its_own_belief_and_the_fruit_match_scores_both():
    """With claims (a tail scale of 4), the state a track claims holds the track's own belief
    beside it, and a matched fruit's ``filter_nees`` is 4 times its ``nees``; without claims
    there is nothing beside the belief and the two are the same."""
    from bve_mj.estimation.belief import Belief
    from bve_mj.estimation.tracks import Track
    from bve_mj.loop.claims import Claims
    from bve_mj.loop.every_fruit import claimed
    from bve_mj.loop.mujoco_fruits import FruitMatch
    from bve_mj.sim.scene_model import Fruit

    centre = np.array([0.45, 0.02, 0.20])
    track = Track(0, Belief(np.r_[centre + [0.0005, 0.0, -0.0003], 0.03], np.eye(4) * 1e-7), 0, 4, hits=4)
    fruit = Fruit("f", centre, 0.03, "red")
    wide = claimed(track, Claims(tail_scale=4.0), stop_sigma_m=0.002, converge_after=3)
    plain = claimed(track, None, stop_sigma_m=0.002, converge_after=3)
    assert wide.filter_belief is track.belief and plain.filter_belief is None
    m = FruitMatch(fruit, wide)
    assert m.filter_nees == pytest.approx(4.0 * m.nees)
    assert FruitMatch(fruit, plain).filter_nees == pytest.approx(FruitMatch(fruit, plain).nees)


def test_the_every_fruit_table_reports_the_claimed_radius_nees():
    """A tracked fruit's radius NEES is ((r̂ - r) / σ_r)² of its claimed belief; the summary
    averages it over the tracked fruit and the table prints it as ``r NEES``; beside the
    share localised at the end, the share localised after the first 10 views."""
    from types import SimpleNamespace

    from bve_mj.campaigns.fruit_suite import FruitSuiteResult, format_fruit_suite
    from bve_mj.campaigns.runs import radius_metrics

    belief = Belief(np.r_[0.45, 0.0, 0.2, 0.0302], np.diag([1e-8, 1e-8, 1e-8, 1e-8]))  # σ_r 0.1 mm
    assert radius_metrics(belief, 0.030)["radius_nees"] == pytest.approx(4.0)
    assert radius_metrics(Belief(np.array([0.45, 0.0, 0.2]), np.eye(3) * 1e-8), 0.030)["radius_nees"] is None
    rows = (_row(0, 5), _row(1, 6))
    rows[0]["fruits"][0]["radius_nees"], rows[1]["fruits"][0]["radius_nees"] = 4.0, 2.0
    rows[0]["localised_in_budget"], rows[1]["localised_in_budget"] = 1, 0  # the second after 10 views
    result = FruitSuiteResult((SimpleNamespace(name="truss", description=""),), {"truss": rows}, 0, 2, 1.0)
    summary = result.summary("truss")
    assert summary["radius_nees_mean"] == pytest.approx(3.0)
    assert summary["localised_pct"] == 100.0 and summary["localised_in_budget_pct"] == 50.0
    head, _, line, _ = format_fruit_suite({"truss": summary})
    assert "r NEES" in head and "3.00" in line.split()
    assert head.split()[3:5] == ["loc%", "loc%@10"] and line.split()[3:5] == ["100.0", "50.0"]


def test_planners_compared_in_one_pool_give_each_planners_own_suite():
    """``--planners``: every planner on each seed in turn (one scene built per seed) gives
    each planner the rows its own suite gives, in run order."""
    from bve_mj.campaigns.fruit_suite import run_fruit_suite, run_fruit_suites
    from bve_mj.campaigns.scenarios import Scenario, suite_dir
    from bve_mj.errors import ConfigError

    def stable(rows):
        return [{k: v for k, v in r.items() if not k.endswith(("_ms", "wall_s"))} for r in rows]

    sc = [Scenario("plant_trusses", suite_dir() / "plant_trusses.toml", "")]
    together = run_fruit_suites(sc, ("bve", "random"), seeds=2, seed=31)
    for planner in ("bve", "random"):
        alone = run_fruit_suite(sc, seeds=2, seed=31, planner=planner)
        assert [r["run"] for r in together[planner].rows["plant_trusses"]] == [0, 1]
        assert stable(together[planner].rows["plant_trusses"]) == stable(alone.rows["plant_trusses"])
    with pytest.raises(ConfigError, match="planners"):
        run_fruit_suites(sc, ("bve", "bve"), seeds=1)


def test_with_a_miscalibrated_camera_every_track_carries_the_biases_and_claims_what_it_has():
    """`ripe_truss` through the realistic sensors (2 px principal point, 1% focal), seed
    2900375763: before the tracks carried the camera's calibration biases, three fruit ended
    claimed localised with the truth outside their 99.9% ellipsoid; each track's state now
    holds the biases (7,), as the one-target filter's does, and every fruit it claims is
    inside. (Since the noise model's neighbour-weighted fit and close-view terms, κ² 1.55 →
    2.81, two of the five fruit end tracked 1.3-1.7 mm off but not claimed after 16 views.)"""
    from bve_mj.campaigns.scenarios import suite_dir
    from bve_mj.loop.mujoco_fruits import run_every_fruit_episode

    sensor = {"image_noise_std": 2.0, "focal_error_rel": 0.01, "principal_point_error_px": 2.0}
    s = with_overrides(
        load_settings(suite_dir() / "ripe_truss.toml"),
        sensor={**sensor, "encoder_noise_rad": 0.0004},
        tracking={"fruits": "all"},
    )
    ep = run_every_fruit_episode(s, 2900375763)
    states = [f for v in ep.result.views for f in v.fruits]
    assert states and all(f.belief.dim == 7 for f in states)
    matches, _, _ = ep.matches()
    claimed = [m for m in matches if m.track is not None and m.track.localised]
    assert sum(m.localised_within(5.0) for m in matches) >= 3
    assert claimed and all(m.nees <= 16.27 for m in claimed), [round(m.nees, 1) for m in claimed]


def test_a_tracks_claim_adds_the_offset_of_what_the_detector_saw_of_it():
    """The claim's centre offset is the noise model's, conditioned on the neighbour shares of
    the views the track fused (a fruit touching its neighbours is off by more than a lone
    one, and a lone one by less than the bound over all fruits); where a view's outline is
    not known, the bound over all fruits."""
    from bve_mj.estimation.belief import Belief
    from bve_mj.estimation.noise import Outline, load_noise_model
    from bve_mj.estimation.tracks import Track
    from bve_mj.loop.claims import Claims
    from bve_mj.loop.every_fruit import claimed

    noise = load_noise_model()
    claims = dataclasses.replace(Claims.of_detector(noise, 0.03, None), tail_scale=1.0, refusal_scale=0.0)
    centre = np.array([0.45, 0.02, 0.20])

    def offset(outlines):
        track = Track(0, Belief(np.r_[centre, 0.03], np.eye(4) * 1e-9), 0, 3, hits=3, outlines=outlines)
        state = claimed(track, claims, stop_sigma_m=0.002, converge_after=3)
        return state.belief.cov[:3, :3] - np.eye(3) * 1e-9

    lone, touching = offset([Outline(0.0)] * 3), offset([Outline(0.6)] * 3)
    bound = noise.centre_bias_cov(0.03)
    assert np.allclose(lone, noise.centre_offset_cov(0.03, 1.0, [Outline(0.0)] * 3))
    assert np.trace(lone) < np.trace(bound) < np.trace(touching)
    assert np.allclose(offset([Outline(0.0), None, Outline(0.0)]), bound)
