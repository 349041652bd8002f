"""Seeded closed-loop scenario checks in the rendered greenhouse."""

import dataclasses
import json

import imageio.v2 as imageio
import mujoco
import numpy as np
import pytest

from bve_mj.cli import main
from bve_mj.config import Settings, with_overrides
from bve_mj.loop.mujoco import run_mujoco_episode
from bve_mj.reporting.video import EpisodeRecorder
from bve_mj.robot import arm_kinematics
from bve_mj.sim.scene_model import Fruit

CAMERA = with_overrides(Settings(), measurement={"kind": "camera"})


def _check_joint_limits(ep):
    kin = arm_kinematics(ep.settings.robot.name, ep.settings.robot.limit_set)
    for v in ep.to_json()["views"]:
        q = np.array(v["q_rad"])
        assert np.all(q >= kin.limits.lower - 1e-3) and np.all(q <= kin.limits.upper + 1e-3)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_clear_scene_localised_within_10_mm_in_15_views(seed):
    ep = run_mujoco_episode(CAMERA, seed, leaves=False, distractors=())
    assert len(ep.result.views) - 1 <= 15
    assert ep.final_error_mm < 10.0
    assert ep.result.outcome in ("converged", "stable", "max_views")
    _check_joint_limits(ep)


def test_leaf_partly_covering_the_fruit_within_20_mm():
    target = Fruit("target", np.array([0.42, 0.02, 0.22]), 0.034, "red")

    def leaf(spec):  # a leaf hanging 5 cm in front of the fruit, over its +y side
        spec.worldbody.add_geom(
            name="occluding_leaf", type=mujoco.mjtGeom.mjGEOM_ELLIPSOID, size=[0.003, 0.035, 0.06],
            pos=target.centre_m + np.array([-0.05, 0.045, 0.0]), rgba=[0.16, 0.42, 0.12, 1.0],
            contype=0, conaffinity=0, group=1,
        )  # fmt: skip

    ep = run_mujoco_episode(CAMERA, 4, target=target, edit=leaf)
    doc = ep.to_json()
    trimmed = [
        v["detection"]["trimmed_fraction"]
        for v in doc["views"]
        if "trimmed_fraction" in v.get("detection", {})
    ]
    assert max(trimmed) > 0.15  # the leaf did hide part of the silhouette in some view
    assert ep.final_error_mm < 20.0
    _check_joint_limits(ep)


def test_views_that_measured_nothing_send_the_camera_elsewhere():
    """``beefsteak`` of the suite, episode seed 2461242679 (held out: run of base seed 7321):
    the big fruit is hidden from most of the views the BVE prefers. Before the failed views'
    cost (``planner.untried_weight``), the arm held still among them, each view measuring
    nothing, until the stall rule ended the episode ``unreliable`` 12.9 mm off after one
    measurement; with ``untried_weight = 0`` it still does (broken on purpose). It ends
    ``stalled`` 1.8 mm off since views from one place no longer make an estimate ``stable``
    (its last views were 2.4, 0.9 and 0.5 mm apart)."""
    from bve_mj.campaigns.scenarios import suite_dir
    from bve_mj.config import load_settings

    ep = run_mujoco_episode(load_settings(suite_dir() / "beefsteak.toml"), 2461242679)
    assert sum(v.accepted for v in ep.result.views) >= 3
    assert ep.result.outcome in ("converged", "stable", "stalled"), ep.result.outcome
    assert ep.final_error_mm < 5.0


def test_approach_ends_close_without_touching_or_crossing_the_row():
    """Seed 2. Seeds 1-8 end ``approached`` in 7 of 8: since the detector fits the fruit's lean
    and the noise model was refitted with it, seed 1 ends ``unreliable`` (its first detection
    puts the fruit 64 mm off along the ray; the next view, planned from a slightly different
    covariance, disagrees at NIS 27.7 and is gated, the belief is reset); before, seed 2 stalled
    0.107 m away (``approach_blocked``), and before the refit with interior edges seed 4 ended
    ``unreliable``."""
    s = with_overrides(CAMERA, episode={"approach": True, "views": 25})
    target = Fruit("target", np.array([0.40, 0.0, 0.25]), 0.04, "red")
    ep = run_mujoco_episode(s, 2, target=target)
    assert ep.result.outcome == "approached"
    row_x = s.scene.row_x_m
    for v in ep.result.views:
        gap = np.linalg.norm(v.p_world_camera - target.centre_m)
        assert gap > target.radius_m + 0.01  # never touches the fruit
        assert v.p_world_camera[0] < row_x  # never crosses the plant row
    assert np.linalg.norm(ep.result.views[-1].p_world_camera - target.centre_m) <= 0.1 + 2e-3
    _check_joint_limits(ep)


def test_video_decodes_with_the_expected_frame_count(tmp_path):
    path = tmp_path / "episode.mp4"
    recorder = EpisodeRecorder(path)
    ep = run_mujoco_episode(with_overrides(CAMERA, episode={"views": 3}), 1, recorder=recorder)
    written = recorder.close()
    reader = imageio.get_reader(str(path))
    frames = [f for f in reader]  # (list() would ask the ffmpeg reader for an infinite length)
    assert written == len(frames) == reader.count_frames() > len(ep.result.views) * recorder.hold_frames
    assert frames[0].shape == (480, 1280, 3)


def test_episode_cli_json_and_bad_input(tmp_path, capsys):
    out = tmp_path / "ep.json"
    assert main(["episode", "--seed", "1", "--views", "3", "--json", str(out), "--quiet"]) == 0
    doc = json.loads(out.read_text())
    for key in ("settings", "seed", "views", "final_error_mm", "outcome", "wall_s"):
        assert key in doc
    assert doc["seed"] == 1 and doc["views"][0]["view"] == 0
    for key in (
        "q_rad",
        "camera_position_m",
        "detection",
        "estimate_m",
        "covariance_m2",
        "truth_m",
        "timings_s",
    ):
        assert key in doc["views"][1]
    capsys.readouterr()
    for argv, field in (
        (["episode", "--views", "0"], "views"),
        (["episode", "--video", str(tmp_path / "x.avi")], "video"),
        (["episode", "--experiment", "E42"], "episode.experiment"),
        (["episode", "--measurement", "sonar"], "measurement.kind"),
    ):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and field in err


@pytest.mark.parametrize("seed", [0, 1, 2, 3, 4])
def test_approach_arrives_or_says_why_not(seed):
    """The default approach episode: within 0.1 m of the fruit, or an outcome naming why not
    (the arm was blocked; or the fruit was measured in too few views to trust the estimate it
    drove to: seed 4 since the claims hold the tail, where the first planned view saw only
    80° of the fruit behind a leaf and no later one fitted it)."""
    s = with_overrides(Settings(), episode={"approach": True})
    ep = run_mujoco_episode(s, seed)
    last, outcome = ep.result.views[-1], ep.result.outcome
    gap = float(np.linalg.norm(last.p_world_camera - ep.result.final.centre_m))
    assert outcome in ("approached", "approach_blocked", "unreliable")
    if outcome == "unreliable":  # said, with the reason: fewer than two measurements
        assert outcome.note and sum(v.accepted for v in ep.result.views) < 2
    else:
        assert (gap <= s.episode.approach_distance_m) == (outcome == "approached")
        assert ep.final_error_mm < 2.0
    _check_joint_limits(ep)


def test_a_camera_that_stops_moving_ends_the_episode():
    """Repeating one view fuses the same errors again: the loop stops ("stalled") instead of
    taking all its views, and "approach_blocked" in approach mode."""
    from bve_mj.estimation.belief import Belief
    from bve_mj.loop.episode import StopRules, ViewRecord

    def view(i, p):
        b = Belief(np.zeros(3), np.eye(3) * 1e-2)  # far from converged
        return ViewRecord(i, np.asarray(p, float), None, True, 0.0, True, False, 1.0, b)

    still = [view(i, [0.2, 0.0, 1e-3 * i]) for i in range(5)]
    moving = [view(i, [0.2, 0.0, 0.01 * i]) for i in range(5)]
    rules = StopRules(sigma_m=1e-3, stable_m=1e-4, stall_m=0.005)
    assert rules.outcome(still) == "stalled" and rules.outcome(moving) is None
    assert rules.outcome(still[:3]) is None  # needs stable_views views after the first
    approach = StopRules(approach_distance_m=0.1, stall_m=0.005)
    assert approach.outcome(still) == "approach_blocked" and approach.outcome(moving) is None


def test_an_estimate_that_stops_moving_on_accepted_views_is_stable():
    """ "stable": the estimate moved less than stable_m over stable_views views, each with an
    accepted measurement; a gated-out view is no agreement, and a moving estimate is not."""
    from bve_mj.estimation.belief import Belief
    from bve_mj.loop.episode import StopRules, ViewRecord

    def view(i, x, accepted=True):
        b = Belief(np.array([x, 0.0, 0.2]), np.eye(3) * 1e-4)  # σ 10 mm: not converged
        return ViewRecord(i, np.array([0.2, 0.01 * i, 0.0]), None, True, 0.0, True, accepted, 1.0, b)

    rules = StopRules(sigma_m=1e-3, stable_m=5e-4, stable_views=3)
    settled = [view(i, 0.4 + 1e-4 * i) for i in range(5)]
    assert rules.outcome(settled) == "stable"
    assert rules.outcome(settled[:3]) is None  # needs stable_views moves
    assert rules.outcome([*settled[:4], view(4, 0.4004, accepted=False)]) is None
    drifting = [view(i, 0.4 + 1e-3 * i) for i in range(5)]
    assert rules.outcome(drifting) is None
    assert StopRules(sigma_m=1e-3).outcome(settled) is None  # the rule off


def test_views_from_one_place_do_not_make_an_estimate_stable():
    """A view taken where the last one was repeats its error (range-only: the apparent size's
    bias), so the estimate holding still under it is no evidence: "stable" needs each of the
    stable_views views at least stall_m from the one before (seen in truss_cluster, range,
    seed 3025393228: views 6, 1 and 0.4 mm apart held an estimate 11.8 mm off claiming σmax
    8.7 mm). Apart by 10 mm the same estimates are stable."""
    from bve_mj.estimation.belief import Belief
    from bve_mj.loop.episode import StopRules, ViewRecord

    def views(y_m):
        b = [Belief(np.array([0.4 + 1e-5 * i, 0.0, 0.2]), np.eye(3) * 1e-4) for i in range(len(y_m))]
        return [
            ViewRecord(i, np.array([0.2, y, 0.0]), None, True, 0.0, True, True, 1.0, b[i])
            for i, y in enumerate(y_m)
        ]  # σ 10 mm: not converged; every view accepted

    rules = StopRules(sigma_m=1e-3, stable_m=5e-4, stable_views=3, stall_m=0.005)
    assert rules.outcome(views([0.0, 0.01, 0.02, 0.03, 0.04])) == "stable"
    assert rules.outcome(views([0.0, 0.01, 0.02, 0.03, 0.031])) is None  # the last 1 mm from the one before
    assert rules.outcome(views([0.0, 0.003, 0.006, 0.009, 0.012])) is None  # 3 mm apart: moving, not stable
    assert rules.outcome(views([0.0, 0.001, 0.002, 0.003, 0.004])) == "stalled"
    assert StopRules(sigma_m=1e-3, stable_m=5e-4).outcome(views([0.0, 0.0, 0.0, 0.0, 0.0])) == "stable"


def _dispute_views(nis: list[float], directions_deg: list[float], reset_at: int | None = None):
    """Views of a fruit at the origin, every one accepted and converged (σ 0.5 mm) but for its
    NIS and its direction (degrees about z, from the fruit to the camera, 0.25 m away)."""
    from bve_mj.estimation.belief import Belief
    from bve_mj.loop.episode import ViewRecord
    from bve_mj.loop.events import Event

    b = Belief(np.zeros(3), np.eye(3) * 0.5e-3**2)
    views = []
    for i, (n, a) in enumerate(zip(nis, directions_deg, strict=True)):
        p = 0.25 * np.array([np.cos(np.radians(a)), np.sin(np.radians(a)), 0.0])
        events = (Event("belief_reset"),) if i == reset_at else ()
        views.append(ViewRecord(i, p, None, True, 0.0, True, True, n, b, None, events))
    return views


def test_a_view_that_disputes_the_belief_holds_converged_back_until_an_independent_view_agrees():
    """An accepted measurement with NIS beyond the 99.9% quantile says the belief or the view is
    off by more than the noise allows; "converged" waits until a view 30 deg or more from it
    agrees (seen in truss_cluster, seed 3976831502: a dispute at NIS 24 between a side view and
    views from above, "settled" by a view from above, claimed σmax 0.9 mm 4.3 mm off). Views from
    the disputing view's own direction share its error and settle nothing; the first accepted
    view is tested only against the prior; a belief reset starts over."""
    from bve_mj.config import EpisodeConfig
    from bve_mj.loop.episode import StopRules

    rules = StopRules.for_episode(EpisodeConfig(), "camera")
    assert rules.agree_nis == pytest.approx(16.266, abs=1e-3)
    assert StopRules.for_episode(EpisodeConfig(), "range").agree_nis == pytest.approx(10.828, abs=1e-3)
    calm = _dispute_views([40.0, 2.0, 3.0], [0.0, 10.0, 20.0])  # the first: against the prior
    assert rules.outcome(calm) == "converged" and rules.standing_dispute(calm) is None
    disputed = _dispute_views([1.0, 2.0, 24.0], [0.0, 40.0, 80.0])
    assert rules.outcome(disputed) is None and rules.standing_dispute(disputed) is disputed[2]
    same_side = _dispute_views([1.0, 2.0, 24.0, 3.0, 2.0], [0.0, 40.0, 80.0, 95.0, 100.0])
    assert rules.outcome(same_side) is None  # 15 and 20 deg from the disputing view
    settled = _dispute_views([1.0, 2.0, 24.0, 3.0, 2.0], [0.0, 40.0, 80.0, 95.0, 40.0])
    assert rules.outcome(settled) == "converged" and rules.standing_dispute(settled) is None
    again = _dispute_views([1.0, 2.0, 24.0, 3.0, 30.0], [0.0, 40.0, 80.0, 40.0, 0.0])
    assert rules.outcome(again) is None  # the last dispute is the one to settle
    reset = _dispute_views([1.0, 24.0, 50.0, 2.0, 3.0], [0.0, 40.0, 80.0, 120.0, 160.0], reset_at=2)
    assert rules.outcome(reset) == "converged"  # the reset view's own NIS is against the old belief
    off = StopRules.for_episode(EpisodeConfig(agree_views=0), "camera")
    assert off.agree_nis is None and off.outcome(disputed) == "converged"


@pytest.mark.parametrize("name", ["agree_views", "stall_escapes"])
@pytest.mark.parametrize("bad", [-1, 101, 1.5, True, "2"])
def test_agree_views_and_stall_escapes_are_validated(name, bad):
    from bve_mj.config import EpisodeConfig
    from bve_mj.errors import ConfigError

    with pytest.raises(ConfigError, match=rf"episode\.{name}"):
        EpisodeConfig(**{name: bad})


def test_many_views_stop_when_the_view_stops_changing():
    """--views 10000 --approach used to take 10,001 views (283 s) and end with NEES 3727."""
    s = with_overrides(Settings(), episode={"approach": True, "views": 10000})
    ep = run_mujoco_episode(s, 0)
    assert len(ep.result.views) < 40
    assert ep.result.final.mahalanobis_sq(ep.truth) < 16.3  # inside the 99.9% ellipsoid


def test_ready_pose_keeps_off_the_joint_limits():
    for seed in range(5):
        ep = run_mujoco_episode(Settings(), seed, leaves=False)
        kin = arm_kinematics(ep.settings.robot.name, ep.settings.robot.limit_set)
        assert kin.limit_margin(ep.q_start) >= 0.1


def _ready_pose_one_start_at_a_time(kin, estimate, distance, rng, upright):  # type: ignore[no-untyped-def]
    """The ready-pose search as it was before its starts were screened: every start solved
    by the look-at IK, direction by direction, the random starts drawn as each is tried."""
    import math

    from bve_mj.loop.start import START_MARGIN
    from bve_mj.robot import IkOptions, look_at_ik
    from bve_mj.robot.ik import image_roll_rad

    best = None
    single = IkOptions(restarts=0, upright=upright)
    for elevation in (0.15, 0.35, -0.1, 0.6, -0.3):
        for yaw in (0.0, 0.3, -0.3):
            d = np.array([-math.cos(yaw), math.sin(yaw), elevation])
            p = estimate + distance * d / np.linalg.norm(d)
            for seed in (kin.home, *(kin.random_configuration(rng) for _ in range(7))):
                ik = look_at_ik(kin, p, estimate, seed, rng, single)
                if ik.success:
                    margin = kin.limit_margin(ik.q)
                    roll = image_roll_rad(kin.camera_pose(ik.q)[1]) or 0.0
                    key = (min(margin, START_MARGIN), -abs(roll)) if upright else (margin, 0.0)
                    if best is None or key > best[0]:
                        best = (key, ik.q)
            if best is not None and best[0][0] >= START_MARGIN:
                return best[1]
    return np.full(kin.nq, np.nan) if best is None else best[1]


@pytest.mark.parametrize("upright", [False, True])
def test_ready_pose_search_screens_starts_without_changing_its_answer(upright):
    """The starts screened out by the batched solve are starts that fail: the search gives
    the pose of a search that solves every start one by one, to the bit, and leaves its
    random generator in the same state."""
    from bve_mj.errors import PlanningError
    from bve_mj.loop.start import _start_configuration

    kin = arm_kinematics("manipulator_h", "urdf")
    estimates = np.random.default_rng(5).uniform([0.2, -0.25, 0.2], [0.7, 0.25, 0.7], (12, 3))
    found = 0
    for i, estimate in enumerate(estimates):
        rng, rng_ref = np.random.default_rng(i), np.random.default_rng(i)
        try:
            q = _start_configuration(kin, estimate, 0.3, rng, upright=upright)
        except PlanningError:
            q = np.full(kin.nq, np.nan)
        q_ref = _ready_pose_one_start_at_a_time(kin, estimate, 0.3, rng_ref, upright)
        np.testing.assert_array_equal(q, q_ref)
        assert rng.random() == rng_ref.random()
        found += bool(np.isfinite(q).all())
    assert found >= 10


def test_the_ready_pose_sees_the_target_its_first_detection_was_of():
    """The detection prior is a first detection of the target from the ready pose, so that
    pose must see it. With a ripe fruit 65 mm in front of the target on the line of sight of
    the ready pose it would have had (a fruit hidden behind its neighbour: the neighbour
    would have been detected), the ready pose looks from another direction, one that sees the
    target, and the prior's ray passes through it. The cube prior (nothing detected) keeps
    the pose, from which the target is hidden; so does the detection prior where no pose the
    search reaches sees it (seed 0: only the highest directions keep off the joint limits)."""
    from bve_mj.loop.mujoco import episode_settings
    from bve_mj.loop.start import START_VISIBLE_SHARE, _sees_fruit, start_episode

    target = Fruit("target", np.array([0.42, 0.0, 0.25]), 0.03, "red")
    detection = episode_settings(CAMERA)
    cube = with_overrides(detection, episode={"prior": "cube"})
    moved = 0
    for seed in range(4):
        alone = start_episode(cube, seed, target=target, distractors=(), leaves=False)
        assert alone.q_start is not None
        los = alone.kin.camera_pose(alone.q_start)[0] - target.centre_m
        front = (Fruit("front", target.centre_m + 0.065 * los / np.linalg.norm(los), 0.03, "red"),)
        hidden = start_episode(cube, seed, target=target, distractors=front, leaves=False)
        sees = _sees_fruit(hidden.model, hidden.kin, target)
        np.testing.assert_array_equal(hidden.q_start, alone.q_start)
        assert not sees(alone.q_start)
        start = start_episode(detection, seed, target=target, distractors=front, leaves=False)
        if seed == 0:
            np.testing.assert_array_equal(start.q_start, alone.q_start)
            continue
        assert start.q_start is not None and sees(start.q_start)
        p_camera = start.kin.camera_pose(start.q_start)[0]
        ray = (target.centre_m - p_camera) / np.linalg.norm(target.centre_m - p_camera)
        offset = start.prior.mean[:3] - target.centre_m
        assert np.linalg.norm(offset - (offset @ ray) * ray) < target.radius_m  # on the ray, near its centre
        moved += not np.allclose(start.q_start, alone.q_start)
    assert moved == 3 and 0.5 < START_VISIBLE_SHARE < 1.0


class _Scripted:
    """A world that measures, view after view, the listed points directly (1 mm noise)."""

    def __init__(self, points):  # type: ignore[no-untyped-def]
        self.points, self.view = [np.asarray(p, float) for p in points], 0

    p_world_camera = np.zeros(3)

    def move_camera(self, plan) -> None:  # type: ignore[no-untyped-def]
        pass

    def observe(self, belief=None):  # type: ignore[no-untyped-def]
        from bve_mj.estimation.models import CameraModel
        from bve_mj.sim.world import Observation

        p = self.points[min(self.view, len(self.points) - 1)]
        self.view += 1
        return Observation(p.copy(), CameraModel(np.zeros(3), np.eye(3), np.eye(3) * 1e-6))


class _Still:
    def plan(self, belief, p_world_camera, iteration):  # type: ignore[no-untyped-def]
        from bve_mj.planning.plan import ViewPlan

        return ViewPlan(np.zeros(3), belief.centre_m.copy(), "optimal", True, 0.0)


@pytest.mark.parametrize(
    ("later", "outcome"),
    [
        ([0.42, 0.0, 0.20], "unreliable"),  # two later views agree on another place the prior allows
        ([0.40, 0.0, 0.20], "max_views"),  # they agree with the first views
        ([0.40, 0.3, 0.20], "max_views"),  # another place the prior rules out: a false detection
    ],
)
def test_two_gated_out_views_that_agree_on_another_answer_end_unreliable(later, outcome):
    """The first views fuse one place; two later ones agree on another, 2 cm off, that the
    prior allows, and the gate rejects them: the evidence holds two answers, so the episode
    says so (``unreliable``) instead of claiming the first (a truss episode did: NEES 176)."""
    from bve_mj.config import FilterConfig
    from bve_mj.estimation.belief import Belief
    from bve_mj.loop.episode import run_episode

    first = [0.40, 0.0, 0.20]
    world = _Scripted([first, first, first, later, later])
    prior = Belief.isotropic(np.array([0.41, 0.0, 0.20]), 0.02)
    cfg = FilterConfig(gate_probability=0.999, reset_after_rejections=3)
    result = run_episode(world, _Still(), prior, cfg, steps=4)
    assert result.outcome == outcome


def test_a_python_call_replays_the_command_lines_episode_whatever_blas_threads_the_caller_has():
    """`run_mujoco_episode` computes with one BLAS thread itself: a caller whose BLAS runs on
    several threads gets the episode `bve-mj episode` prints (this range-only episode ended
    7.1 mm off in a two-thread session and 13.5 mm off from the CLI before it did)."""
    from threadpoolctl import threadpool_limits

    from bve_mj.campaigns.scenarios import load_suite
    from bve_mj.threads import one_blas_thread

    settings = load_suite(only=["truss_mixed_ripeness"])[0].settings("range")
    with threadpool_limits(limits=2, user_api="blas"):
        many = run_mujoco_episode(settings, 1575926413)
    with one_blas_thread():
        one = run_mujoco_episode(settings, 1575926413)
    np.testing.assert_array_equal(many.result.final.mean, one.result.final.mean)
    assert len(many.result.views) == len(one.result.views)


def test_views_record_the_filters_own_belief_beside_a_wider_claim():
    """With claims (here a tail scale of 4), each view records the claim and the filter's own
    belief: the claim's covariance is 4 times the filter's, so its NEES is a quarter of the
    filter's; without claims there is nothing beside the belief (``final_filter`` is it)."""
    from bve_mj.config import FilterConfig
    from bve_mj.estimation.belief import Belief
    from bve_mj.loop.claims import Claims
    from bve_mj.loop.episode import run_episode

    truth = np.array([0.40, 0.0, 0.20])
    points = [truth + [0.001, -0.002, 0.0], truth + [-0.001, 0.001, 0.001], truth + [0.0, 0.001, -0.002]]
    prior = Belief.isotropic(np.array([0.41, 0.0, 0.20]), 0.02)
    cfg = FilterConfig()
    claimed = run_episode(_Scripted(points), _Still(), prior, cfg, steps=2, claims=Claims(tail_scale=4.0))
    plain = run_episode(_Scripted(points), _Still(), prior, cfg, steps=2)
    for v, p in zip(claimed.views, plain.views, strict=True):
        assert v.filter_belief is not None and p.filter_belief is None
        np.testing.assert_array_equal(v.filter_belief.mean, p.belief.mean)
        np.testing.assert_allclose(v.belief.cov, 4.0 * v.filter_belief.cov)
    filter_nees = claimed.final_filter.mahalanobis_sq(truth)
    assert filter_nees == pytest.approx(plain.final.mahalanobis_sq(truth))
    assert claimed.final.mahalanobis_sq(truth) == pytest.approx(filter_nees / 4.0)
    assert plain.final_filter is plain.final


def test_a_heavy_tailed_claim_changes_what_is_claimed_not_what_the_loop_decides():
    """A claim's shape (a Student-t whose bound is ρ = 3 times its covariance) leaves every
    view's belief, the loop's bound, as the Gaussian claim with the same tail scale has it;
    the episode's claim is the bound's covariance over ρ, its NEES ρ times the bound's."""
    from bve_mj.config import FilterConfig
    from bve_mj.estimation.belief import Belief
    from bve_mj.estimation.claim_shape import ClaimShape
    from bve_mj.loop.claims import Claims
    from bve_mj.loop.episode import run_episode

    truth = np.array([0.40, 0.0, 0.20])
    points = [truth + [0.001, -0.002, 0.0], truth + [-0.001, 0.001, 0.001], truth + [0.0, 0.001, -0.002]]
    prior = Belief.isotropic(np.array([0.41, 0.0, 0.20]), 0.02)
    cfg = FilterConfig()
    shaped = run_episode(
        _Scripted(points), _Still(), prior, cfg, steps=2, claims=Claims(tail_scale=4.0, shape=ClaimShape(3.0))
    )
    gaussian = run_episode(_Scripted(points), _Still(), prior, cfg, steps=2, claims=Claims(tail_scale=4.0))
    assert shaped.outcome == gaussian.outcome
    for v, g in zip(shaped.views, gaussian.views, strict=True):
        np.testing.assert_array_equal(v.belief.mean, g.belief.mean)
        np.testing.assert_array_equal(v.belief.cov, g.belief.cov)
        np.testing.assert_allclose(shaped.claim(v).cov * 3.0, v.belief.cov)
    assert shaped.shape == ClaimShape(3.0) and gaussian.shape.bound_scale == 1.0
    assert shaped.final_claim.mahalanobis_sq(truth) == pytest.approx(3.0 * shaped.final.mahalanobis_sq(truth))
    assert gaussian.final_claim is gaussian.final


class _Listening(_Still):
    """A planner that records the views it is told failed."""

    def __init__(self):  # type: ignore[no-untyped-def]
        self.failed: list[np.ndarray] = []

    def note_failed_view(self, p_world_camera, p_world_target):  # type: ignore[no-untyped-def]
        self.failed.append(np.asarray(p_world_camera, float).copy())


def test_a_standing_dispute_holds_the_claim_back_and_sends_the_planner_elsewhere():
    """Two views agree, a third disputes them (10 mm off at σ 1 mm, not gated) and the views
    after it all come from its direction: no view settles the dispute, so the episode never
    says converged (it would after three views without the rule), and the planner is told of
    each disputing view once, as a view that failed, so that it looks from elsewhere."""
    from bve_mj.config import FilterConfig
    from bve_mj.estimation.belief import Belief
    from bve_mj.estimation.metrics import chi2_quantile
    from bve_mj.loop.episode import StopRules, run_episode

    truth = np.array([0.40, 0.0, 0.20])
    off = truth + [0.0, 0.010, 0.0]
    prior = Belief.isotropic(np.array([0.41, 0.0, 0.20]), 0.02)
    rules = StopRules(sigma_m=1.5e-3, min_accepted=3, agree_nis=float(chi2_quantile(0.999, 3)))
    planner = _Listening()
    world = _Scripted([truth, truth, off, off, off, off])
    result = run_episode(world, planner, prior, FilterConfig(), steps=5, stop=rules)
    assert result.views[2].nis > rules.agree_nis and result.outcome == "max_views"
    disputing = [v for v in result.views[1:] if v.nis > rules.agree_nis]
    assert len(planner.failed) == len(disputing)  # each disputing view told once, not once a view
    np.testing.assert_array_equal(planner.failed[0], result.views[2].p_world_camera)
    calm = run_episode(_Scripted([truth] * 6), _Listening(), prior, FilterConfig(), steps=5, stop=rules)
    assert calm.outcome == "converged" and len(calm.views) == 3
    plain = StopRules(sigma_m=1.5e-3, min_accepted=3)
    world = _Scripted([truth, truth, off, off, off, off])
    undisputed = run_episode(world, _Listening(), prior, FilterConfig(), steps=5, stop=plain)
    assert undisputed.outcome == "converged"


class _Axes(_Scripted):
    """A world whose view k measures the point directly, precisely (0.1 mm) along the axes
    ``axes[k]`` only (1 m along the others)."""

    def __init__(self, point, axes):  # type: ignore[no-untyped-def]
        super().__init__([point] * len(axes))
        self.axes = axes

    def observe(self, belief=None):  # type: ignore[no-untyped-def]
        import dataclasses

        obs = super().observe(belief)
        sigma = np.ones(3)
        sigma[list(self.axes[min(self.view - 1, len(self.axes) - 1)])] = 1e-4
        model = dataclasses.replace(obs.model, noise_cov_camera=np.diag(sigma**2))
        return dataclasses.replace(obs, model=model)


def test_converged_needs_an_answer_that_rests_on_no_single_view():
    """View 0 alone measures x; views 1 and 2 measure y and z: σmax is 0.1 mm after three
    views, but without view 0 the claim is the prior's 20 mm along x, so the redundant rule
    waits for view 3, which measures x again (the plain rule converges at view 2). Each
    leave-one-out belief is the exact Kalman filter's (information form) without that view."""
    from bve_mj.config import FilterConfig
    from bve_mj.estimation.belief import Belief
    from bve_mj.loop.episode import EpisodeLoop, StopRules, run_episode

    truth = np.array([0.40, 0.0, 0.20])
    prior = Belief.isotropic(np.array([0.41, 0.01, 0.19]), 0.02)
    axes = [(0,), (1, 2), (1, 2), (0,), (1, 2)]
    rules = StopRules(sigma_m=1.5e-3, min_accepted=3, redundant=True)
    plain = dataclasses.replace(rules, redundant=False)
    assert run_episode(_Axes(truth, axes), _Still(), prior, FilterConfig(), 4, plain).outcome == "converged"
    result = run_episode(_Axes(truth, axes), _Still(), prior, FilterConfig(), 4, rules)
    assert result.outcome == "converged" and len(result.views) == 4
    assert result.views[2].belief.sigma_max_m < 1e-3  # the plain rule's stop, held back

    loop = EpisodeLoop(_Axes(truth, axes), prior, FilterConfig(process_sigma_m=0.0), _Still())
    assert loop.leave_one_out() == []
    loop.start()
    assert [b.sigma_max_m for b in loop.leave_one_out()] == [prior.sigma_max_m]  # one view: the prior
    for i in range(1, 4):
        if i == 3:  # views 0-2: without view 0, x is the prior's
            assert loop.leave_one_out()[0].sigma_max_m > 0.01 > loop.leave_one_out()[1].sigma_max_m
        loop.step(_Still().plan(loop.belief, np.zeros(3), i))
    info0 = np.linalg.inv(prior.cov)
    for k, left in enumerate(loop.leave_one_out()):
        info, vec = info0.copy(), info0 @ prior.mean
        for j, ax in enumerate(axes[:4]):
            if j != k:
                sigma = np.ones(3)
                sigma[list(ax)] = 1e-4
                info += np.diag(sigma**-2)
                vec += np.diag(sigma**-2) @ truth
        np.testing.assert_allclose(left.cov, np.linalg.inv(info), rtol=1e-6, atol=1e-16)
        np.testing.assert_allclose(left.mean, np.linalg.solve(info, vec), atol=1e-9)
    wide, asked = Belief.isotropic(truth, 0.01), []

    def ask():  # type: ignore[no-untyped-def]
        asked.append(1)
        return [wide]

    assert rules.outcome(loop.views, ask) is None and asked
    asked.clear()
    assert dataclasses.replace(rules, sigma_m=1e-6).outcome(loop.views, ask) is None and not asked


def test_a_stalled_camera_is_sent_elsewhere_before_a_stall_ends_the_episode():
    """A camera that stalls (three planned views within ``stall_m``) tells a planner that learns
    from failed views that the view it holds at is spent, up to ``stall_escapes`` times (event
    ``stall_escaped`` on the next view), and the episode goes on; the next stall after that
    ends it, as does one at the last view of the budget. A planner that cannot learn ends at
    the first stall, and so does approach mode's ``approach_blocked`` (no escapes there)."""
    from bve_mj.config import EpisodeConfig, FilterConfig
    from bve_mj.estimation.belief import Belief
    from bve_mj.loop.episode import StopRules, run_episode

    truth = np.array([0.40, 0.0, 0.20])
    prior = Belief.isotropic(np.array([0.41, 0.0, 0.20]), 0.02)
    rules = StopRules(stall_m=0.005, stable_views=3, stall_escapes=2)
    planner = _Listening()
    result = run_episode(_Scripted([truth] * 12), planner, prior, FilterConfig(), steps=10, stop=rules)
    assert result.outcome == "stalled" and len(result.views) == 6
    assert len(planner.failed) == 2
    assert [v.has("stall_escaped") for v in result.views] == [False] * 4 + [True, True]
    deaf = run_episode(_Scripted([truth] * 12), _Still(), prior, FilterConfig(), steps=10, stop=rules)
    assert deaf.outcome == "stalled" and len(deaf.views) == 4
    none = dataclasses.replace(rules, stall_escapes=0)
    first = run_episode(_Scripted([truth] * 12), _Listening(), prior, FilterConfig(), steps=10, stop=none)
    assert first.outcome == "stalled" and len(first.views) == 4
    last = _Listening()  # a stall at the last view planned: no view left to look elsewhere from
    end = run_episode(_Scripted([truth] * 12), last, prior, FilterConfig(), steps=3, stop=rules)
    assert end.outcome == "stalled" and len(end.views) == 4 and not last.failed
    assert StopRules.for_episode(EpisodeConfig(stall_escapes=3), "camera").stall_escapes == 3
    assert StopRules.for_episode(EpisodeConfig(approach=True), "camera").stall_escapes == 0
