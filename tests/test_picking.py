"""Pick and look again (`tracking.pick_rounds`): the harvest takes the fruit it reaches off the
plant, the survey goes on for the fruit they hid, and the episode's record joins the rounds."""

from __future__ import annotations

import math
from types import SimpleNamespace

import mujoco
import numpy as np
import pytest

from bve_mj.config import load_settings, with_overrides
from bve_mj.config.tracking import TrackingConfig
from bve_mj.errors import ConfigError
from bve_mj.estimation.belief import Belief
from bve_mj.estimation.tracks import ViewTracking
from bve_mj.loop.fruit_records import FruitsResult, FruitState, FruitsView
from bve_mj.loop.harvest import HarvestResult, Visit
from bve_mj.loop.outcomes import Outcome
from bve_mj.loop.picking import PICK_TOLERANCE_M, picked_fruit, survey_and_pick
from bve_mj.perception.detection import Intrinsics
from bve_mj.planning.zone_coverage import ZoneCoverage


def _state(track: int, x: float, localised: bool = True) -> FruitState:
    belief = Belief(np.array([x, 0.0, 0.3, 0.03]), np.eye(4) * 1e-8)
    return FruitState(track, belief, True, 5, 0, 5, localised)


def _result(first_track: int, n: int, views: int, outcome: Outcome = Outcome.INCOMPLETE) -> FruitsResult:
    states = tuple(_state(first_track + k, 0.1 * k) for k in range(n))
    tracking = ViewTracking((), (), (), (), ())
    vs = tuple(
        FruitsView(i, np.zeros(3), None, None, True, 0.0, 0.0, n, tracking, states) for i in range(views)
    )
    return FruitsResult(vs, 1.0, outcome)


def _visit(track: int, picked: str | None) -> Visit:
    return Visit(track, 0, picked is not None, 0.1, 0.1, 0.05, None, picked)


def test_a_visit_picks_the_fruit_at_its_estimate_and_nothing_off_it():
    fruits = SimpleNamespace(
        fruits=(
            SimpleNamespace(name="a", centre_m=np.array([0.4, 0.0, 0.3])),
            SimpleNamespace(name="b", centre_m=np.array([0.4, 0.05, 0.3])),
        )
    )
    near_a = np.array([0.4, 0.004, 0.3])
    assert picked_fruit(near_a, fruits, ()) == "a"  # type: ignore[arg-type]
    assert picked_fruit(near_a, fruits, ("a",)) is None  # type: ignore[arg-type]  (already taken)
    off = np.array([0.4, 0.0, 0.3 + 1.5 * PICK_TOLERANCE_M])
    assert picked_fruit(off, fruits, ()) is None  # type: ignore[arg-type]


def test_survey_and_pick_surveys_again_while_a_harvest_picks_and_joins_the_rounds():
    """Round 0 finds tracks 0-2 and picks two; round 1 (after the two are dropped) finds tracks
    5-6 and picks one; round 2 picks nothing: the end. The record: the views numbered on, each
    later view's fruit with the basket, every visit with its round, the last outcome."""
    surveys = iter([_result(0, 3, 4), _result(5, 2, 3, Outcome.MAX_VIEWS), _result(7, 1, 2)])
    harvests = iter(
        [
            HarvestResult((0, 1, 2), (_visit(0, "f0"), _visit(1, "f1"), _visit(2, None))),
            HarvestResult((5, 6), (_visit(5, "f5"), _visit(6, None))),
            HarvestResult((7,), (_visit(7, None),)),
        ]
    )
    dropped: list[int] = []
    result, harvest = survey_and_pick(lambda: next(surveys), lambda r: next(harvests), dropped.append, 3)
    assert dropped == [0, 1, 5]
    assert [v.iteration for v in result.views] == list(range(9))
    assert [s.id for s in result.views[4].fruits] == [0, 1, 5, 6]  # the basket, then the tracks
    assert [s.id for s in result.final] == [0, 1, 5, 7]
    assert result.outcome == Outcome.INCOMPLETE and result.wall_s == 3.0
    assert harvest is not None and harvest.order == (0, 1, 2, 5, 6, 7)
    assert [v.round for v in harvest.visits] == [0, 0, 0, 1, 1, 2]
    assert [v.picked for v in harvest.visits if v.picked] == ["f0", "f1", "f5"]


def test_survey_and_pick_stops_at_its_rounds_after_a_converged_survey_and_without_picking():
    calls = []

    def survey() -> FruitsResult:
        calls.append(1)
        return _result(len(calls) * 10, 1, 2)

    def picks(r: FruitsResult) -> HarvestResult:  # takes the survey's one fruit
        return HarvestResult((r.final[0].id,), (_visit(r.final[0].id, f"f{r.final[0].id}"),))

    result, harvest = survey_and_pick(survey, picks, lambda t: None, 1)
    assert len(calls) == 2 and harvest is not None and len(harvest.visits) == 2
    calls.clear()
    result, harvest = survey_and_pick(
        survey, lambda r: HarvestResult((10,), (_visit(10, None),)), lambda t: None, 3
    )
    assert len(calls) == 1 and len(result.views) == 2  # nothing picked: no second survey
    calls.clear()  # a survey that ended converged is not repeated; its harvest still picks
    converged = FruitsResult(_result(0, 1, 2).views, 1.0, Outcome.CONVERGED)
    result, harvest = survey_and_pick(lambda: calls.append(1) or converged, picks, lambda t: None, 3)
    assert len(calls) == 1 and harvest is not None and [v.picked for v in harvest.visits] == ["f0"]
    empty = FruitsResult((), 0.0, Outcome.NEVER_DETECTED)
    assert survey_and_pick(lambda: empty, picks, lambda t: None, 3) == (empty, None)
    for bad in (-1, 1.5, True):
        with pytest.raises(ValueError, match="rounds"):
            survey_and_pick(survey, picks, lambda t: None, bad)  # type: ignore[arg-type]


def test_a_survey_after_a_harvest_frames_again_the_part_of_the_zone_around_what_it_took():
    zone = ZoneCoverage(np.array([0.4, 0.0, 0.3]), 0.15, 0.03, 554.0, 640, 480, 0.8)
    zone.framed[:] = True
    zone.framed[0] = False  # a point no view framed stays to frame
    zone.given_up[1] = True
    picked = np.array([[0.4, 0.0, 0.3]])
    zone.look_again_near(picked, 0.08)
    near = np.linalg.norm(zone.points_m - picked[0], axis=1) <= 0.08
    assert near.any() and not near.all() and not near[0]
    expected = near.copy()
    expected[0] = True
    assert np.array_equal(~zone.framed, expected)
    assert zone.given_up[1] == (not near[1]) and not zone.given_up[near].any()
    for bad in (0.0, math.nan):
        with pytest.raises(ValueError):
            zone.look_again_near(picked, bad)


def test_pick_rounds_is_validated_and_needs_approach_mode():
    assert TrackingConfig().pick_rounds == 0
    for bad in (-1, 11, 2.0, True, "3"):
        with pytest.raises(ConfigError, match=r"tracking\.pick_rounds"):
            TrackingConfig(pick_rounds=bad)  # type: ignore[arg-type]
    from bve_mj.campaigns.scenarios import suite_dir
    from bve_mj.loop.mujoco_fruits import run_every_fruit_episode

    s = with_overrides(
        load_settings(suite_dir() / "truss_cluster.toml"), tracking={"fruits": "all", "pick_rounds": 2}
    )
    with pytest.raises(ConfigError, match=r"tracking\.pick_rounds.*approach"):
        run_every_fruit_episode(s, 1)


def test_a_picked_fruit_and_its_calyx_leave_the_image_and_come_back_when_the_world_closes():
    """The scene compiled for a seed is shared by the process's episodes: picking moves the
    fruit's geoms out of the scene for this world only."""
    from bve_mj.campaigns.scenarios import suite_dir
    from bve_mj.loop.mujoco import episode_settings
    from bve_mj.loop.start import start_episode
    from bve_mj.sim.arm import CAMERA_NAME
    from bve_mj.sim.mujoco_world import MujocoWorld
    from bve_mj.sim.scene_model import fruit_calyx_name, fruit_geom_name

    s = episode_settings(load_settings(suite_dir() / "ripe_truss.toml"))
    st = start_episode(s, 7)
    assert st.q_start is not None
    world = MujocoWorld(s, st.kin, st.model, st.info, st.q_start, st.prior.centre_m, np.random.default_rng(0))
    name = st.info.target.name
    geoms = [st.model.geom(g(name)).id for g in (fruit_geom_name, fruit_calyx_name)]
    before = st.model.geom_pos[geoms].copy()
    p, R = st.kin.camera_pose(world.q)
    intr = Intrinsics.from_camera(s.camera)
    t = R.T @ (st.info.target.centre_m - p)
    u, v = intr.project(t)
    r_px = intr.focal_px * math.tan(math.asin(st.info.target.radius_m / float(np.linalg.norm(t))))
    vv, uu = np.mgrid[0 : s.camera.height_px, 0 : s.camera.width_px]
    disc = np.hypot(uu + 0.5 - u, vv + 0.5 - v) < 0.7 * r_px  # the middle of the target's image

    def red(im: np.ndarray) -> float:
        return float(np.mean((im[disc, 0] > 100) & (im[disc, 0] > im[disc, 1] + 40)))

    seen = world.renderer.render(world.data, CAMERA_NAME).astype(int)
    world.pick(name)
    assert world.picked == (name,)
    after = world.renderer.render(world.data, CAMERA_NAME).astype(int)
    assert red(seen) > 0.9 and red(after) < 0.5, (red(seen), red(after))
    assert np.all(world.data.geom_xpos[geoms, 2] < -10.0)
    with pytest.raises(KeyError):
        world.pick(name)
    with pytest.raises(KeyError):
        world.pick("no such fruit")
    world.close()
    assert np.array_equal(st.model.geom_pos[geoms], before)
    data = mujoco.MjData(st.model)
    mujoco.mj_forward(st.model, data)
    assert np.allclose(data.geom_xpos[geoms[0]], st.info.target.centre_m)


def test_picking_the_cluster_front_uncovers_the_fruit_behind_it():
    """`truss_cluster`, episode seed 9105: the survey alone localises 2 of its 4 ripe fruit
    (the two behind the others show too little outline from any view the arm takes); picking
    what it localised uncovers them, and the next survey localises both: 4 of 4, every fruit
    reached, none touched, nothing claimed wrongly."""
    from bve_mj.campaigns.scenarios import suite_dir
    from bve_mj.loop.mujoco_fruits import run_every_fruit_episode

    s = with_overrides(
        load_settings(suite_dir() / "truss_cluster.toml"),
        tracking={"fruits": "all", "pick_rounds": 3},
        episode={"approach": True},
    )
    ep = run_every_fruit_episode(s, 9105)
    matches, _, false = ep.matches()
    assert len(matches) == 4 and false == []
    assert all(m.localised_within(5.0) for m in matches)
    assert all(m.nees < 16.3 for m in matches)  # inside the 99.9% ellipsoid
    assert ep.harvest is not None
    rounds = {v.round for v in ep.harvest.visits}
    assert len(rounds) >= 2, "the fruit behind were found only after a harvest"
    picked = {v.picked for v in ep.harvest.visits if v.picked}
    assert {m.fruit.name for m in matches} <= picked
    for v in ep.harvest.visits:
        assert v.reached, v.reason
        assert v.clearance_m > 0.0, f"the arm touched a fruit visiting track {v.track}"
    doc = ep.to_json()
    assert doc["harvest"]["picked"] == [v.picked for v in ep.harvest.visits if v.picked]
