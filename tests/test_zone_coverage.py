"""The work zone framed by the views (:mod:`bve_mj.planning.zone_coverage`), and the every-fruit
loop that will not say it found every fruit of a zone it has not framed."""

import math

import numpy as np
import pytest

from bve_mj.config import TrackingConfig
from bve_mj.errors import BveError
from bve_mj.estimation import BearingSizeModel, Belief, filter_update
from bve_mj.estimation.assignment import Sighting
from bve_mj.estimation.tracks import Tracker
from bve_mj.estimation.visibility import visible_arc_deg
from bve_mj.geometry import camera_rotation
from bve_mj.loop.every_fruit import SurveyRound, run_every_fruit
from bve_mj.loop.outcomes import Outcome
from bve_mj.planning.every_fruit import EXPLORE
from bve_mj.planning.plan import ViewPlan
from bve_mj.planning.zone_coverage import GRID_STEPS, ZoneCoverage, zone_grid

F, W, H = 466.0, 640, 480
CENTRE = np.array([0.5, 0.0, 0.3])
RADIUS = 0.03
PRIOR = (0.03, 0.03 * 0.15 / math.sqrt(3.0))


def _coverage(zone_m=0.15):
    return ZoneCoverage(CENTRE, zone_m, RADIUS, F, W, H, 0.8)


def test_the_zone_grid_fills_the_ball_a_quarter_radius_apart():
    pts = zone_grid(CENTRE, 0.2)
    d = np.linalg.norm(pts - CENTRE, axis=1)
    assert len(pts) == 257 and GRID_STEPS == 4
    assert d.max() <= 0.2 + 1e-12 and d.min() == 0.0
    step = np.diff(np.unique(np.round(pts[:, 0], 9)))
    assert np.allclose(step, 0.05)
    with pytest.raises(ValueError, match="radius"):
        zone_grid(CENTRE, 0.0)


def test_a_point_is_framed_in_front_inside_the_border_and_within_range():
    cov = _coverage()
    p = CENTRE - np.array([0.3, 0.0, 0.0])
    R = camera_rotation(p, CENTRE)
    framed = cov.in_image(p, R)
    assert framed[np.argmin(np.linalg.norm(cov.points_m - CENTRE, axis=1))]
    # at 0.3 m the image reaches tan(hfov/2)·0.3 = 0.206 m to the side, less half a fruit's
    # apparent radius: y = 0.15 (at depth 0.3 - 0) is inside, a point 0.25 m aside is not
    t = (cov.points_m - p) @ R
    u = 0.5 * W - F * t[:, 1] / t[:, 0]
    v = 0.5 * H - F * t[:, 2] / t[:, 0]
    margin = 0.5 * F * RADIUS / t[:, 0]
    inside = (u >= margin) & (u <= W - margin) & (v >= margin) & (v <= H - margin)
    assert np.array_equal(framed, inside)
    assert 0 < framed.sum() < len(framed)
    # behind the camera, or beyond the range: never
    back = camera_rotation(p, 2 * p - CENTRE)
    assert not cov.in_image(p, back).any()
    far = ZoneCoverage(CENTRE, 0.15, RADIUS, F, W, H, 0.14)  # the nearest point is 0.15 m off
    assert not far.in_image(p, R).any()


def test_views_add_up_and_the_aim_is_the_middle_of_the_largest_part_not_framed():
    cov = _coverage()
    left = CENTRE + np.array([-0.3, 0.12, 0.0])
    cov.note(left, camera_rotation(left, CENTRE + np.array([0.0, 0.12, 0.0])))
    share = cov.share
    assert 0.0 < share < 1.0 and not cov.complete
    aim = cov.aim_m()
    assert not cov.framed[np.argmin(np.linalg.norm(cov.points_m - aim, axis=1))]
    assert aim[1] < 0.0  # the framed part is on the left (+y): the aim lies right
    right = CENTRE + np.array([-0.3, -0.12, 0.0])
    cov.note(right, camera_rotation(right, CENTRE + np.array([0.0, -0.12, 0.0])))
    assert cov.share > share
    # a part given up is not aimed at again, and stays unframed
    while cov.can_aim:
        cov.give_up(cov.aim_m())
    assert not cov.complete and np.allclose(cov.aim_m(), CENTRE)


def test_seen_from_the_camera_the_aim_is_the_point_whose_view_frames_most_of_the_rest():
    """With the camera's position and the distance views keep, the aim is the unframed point
    whose view (from that distance, on the camera's side) frames the most unframed points:
    checked against every candidate, and it frames more than the middle of the largest patch
    would."""
    cov = ZoneCoverage(CENTRE, 0.3, RADIUS, F, W, H, 0.8, standoff_m=0.25)
    here = CENTRE + np.array([-0.25, 0.05, 0.0])
    cov.note(here, camera_rotation(here, CENTRE))

    def gain(a):
        cam = a + 0.25 * (here - a) / np.linalg.norm(here - a)
        return int(np.count_nonzero(cov.in_image(cam, camera_rotation(cam, a)) & ~cov.framed))

    aim = cov.aim_m(here)
    rest = cov.points_m[~cov.framed]
    assert gain(aim) == max(gain(a) for a in rest) > 0
    assert gain(aim) >= gain(cov.aim_m())  # the largest patch's middle (no camera given)


class _World:
    """Fruit as spheres; a camera that goes where it is told (``reach``: or stays, beyond it)
    and measures every fruit whose outline shows 150° or more, with small noise."""

    def __init__(self, fruit, reach=None):
        self.fruit = [np.asarray(f, dtype=float) for f in fruit]
        self.p = CENTRE - np.array([0.25, 0.0, 0.0])
        self.target = CENTRE.copy()
        self.reach = reach
        self.q_measured = None

    @property
    def p_world_camera(self):
        return self.p

    def move_camera(self, plan):
        if self.reach is None or self.reach(plan.p_world_camera):
            self.p, self.target = plan.p_world_camera.copy(), plan.p_world_target.copy()

    def observe_all(self):
        R = camera_rotation(self.p, self.target)
        centres = np.array(self.fruit)
        seen = visible_arc_deg(centres, np.full(len(centres), RADIUS), self.p, R, F, W, H) >= 150.0
        cov = np.eye(3) * (0.3 / F) ** 2
        model = BearingSizeModel(self.p, R, cov)
        out = [Sighting(model.predict(np.r_[c, RADIUS]), model) for c in centres[seen]]
        return out, model

    def view_info(self):
        return {}


class _Planner:
    """Views 0.25 m from whatever it is asked to look at, from directions that turn by 25°
    a view (so a fruit is seen from several directions, and the views span the zone)."""

    def __init__(self):
        self.k = 0

    def _at(self, aim):
        self.k += 1
        a = math.radians(25.0 * ((self.k % 5) - 2))
        d = np.array([-math.cos(a), math.sin(a), 0.0])
        return ViewPlan(aim + 0.25 * d, aim.copy(), "optimal", True, 0.0)

    def plan(self, fruits, p_world_camera, iteration, q=None):
        worst = max((f for f in fruits if not f.localised), key=lambda f: f.sigma_max_m)
        return self._at(worst.belief.centre_m), worst.id

    def explore(self, zone, p_world_camera, iteration, q=None):
        return self._at(zone.centre_m)

    def forget(self, fruit):
        pass

    def set_configuration(self, q):
        pass

    def note_failed_view(self, fruit, p_world_camera, p_world_target):
        pass

    def note_fused_view(self, fruit, p_world_camera, p_world_target):
        pass

    def note_explored(self, p_world_camera, p_world_target):
        pass


def _episode(world, coverage, zone_m=0.3):
    cfg = TrackingConfig(fruits="all", zone_m=zone_m)

    def visible(c, r, m):
        return visible_arc_deg(c, r, m.p_world_camera, m.R_world_camera, F, W, H) >= 150.0

    tracker = Tracker(cfg, CENTRE, PRIOR, filter_update("ekf", 10), visible)
    sd = zone_m / 2.0
    zone = Belief(np.r_[CENTRE, PRIOR[0]], np.diag([sd**2] * 3 + [PRIOR[1] ** 2]))
    return run_every_fruit(world, _Planner(), tracker, 40, 0.002, 3, zone=zone, coverage=coverage)


def test_a_fruit_the_views_of_its_neighbour_never_frame_is_found_once_the_zone_must_be_framed():
    """Two fruit 0.22 m apart vertically in a zone of 0.3 m: views 0.25 m from the first frame
    ±0.13 m vertically and never show the second. Without the zone check the episode says it
    found every fruit with one; with it, it looks at the part not framed, finds the second and
    localises both before saying so."""
    above = CENTRE + np.array([0.0, 0.0, 0.22])
    blind = _episode(_World([CENTRE, above]), None)
    assert blind.outcome == Outcome.CONVERGED and len(blind.final) == 1

    cov = ZoneCoverage(CENTRE, 0.3, RADIUS, F, W, H, 0.8)
    res = _episode(_World([CENTRE, above]), cov)
    assert res.outcome == Outcome.CONVERGED
    assert len(res.final) == 2 and all(s.localised for s in res.final)
    for truth in (CENTRE, above):
        assert min(np.linalg.norm(s.belief.centre_m - truth) for s in res.final) < 1e-3
    assert res.views[-1].zone_framed == 1.0
    assert any(v.planned_for == EXPLORE for v in res.views)
    assert all(math.isnan(v.zone_framed) for v in blind.views)


def test_a_zone_the_arm_cannot_frame_ends_incomplete_not_converged():
    """The camera cannot go above z = 0.35 m: the top of the zone is never framed. Each view
    aimed there that frames nothing new gives that part up (event ``zone_unframed``); with
    nothing left to aim at the episode ends ``incomplete``, early, not ``converged``."""
    cov = ZoneCoverage(CENTRE, 0.3, RADIUS, F, W, H, 0.8)
    res = _episode(_World([CENTRE], reach=lambda p: p[2] <= 0.35), cov)
    assert res.outcome == Outcome.INCOMPLETE
    assert res.views[-1].zone_framed < 1.0 and len(res.views) < 41
    assert any(e.kind == "zone_unframed" for v in res.views for e in v.events)
    assert all(s.localised for s in res.final)


def test_the_zone_share_setting_is_validated():
    with pytest.raises(Exception, match=r"tracking\.zone_framed_share"):
        TrackingConfig(zone_framed_share=1.5)
    with pytest.raises(Exception, match=r"tracking\.zone_framed_share"):
        TrackingConfig(zone_framed_share=float("nan"))
    assert TrackingConfig(zone_framed_share=0.0).zone_framed_share == 0.0


class _NoView(_Planner):
    """A planner that never finds a view (every candidate's move blocked, say)."""

    def plan(self, fruits, p_world_camera, iteration, q=None):
        raise BveError("no fruit's planner found a viewpoint")

    def explore(self, zone, p_world_camera, iteration, q=None):
        raise BveError("the move to the exploration view passes through a known fruit")


def test_a_planner_that_finds_no_view_draws_the_camera_back_instead_of_holding_it():
    """Where the planner finds no view the camera held sees what it saw; with ``retreat`` the
    view is the one it draws back (event ``retreated``, plan ``fallback``), and where it
    draws none the camera holds."""
    cfg = TrackingConfig(fruits="all", zone_m=0.3)

    def visible(c, r, m):
        return visible_arc_deg(c, r, m.p_world_camera, m.R_world_camera, F, W, H) >= 150.0

    zone = Belief(np.r_[CENTRE, PRIOR[0]], np.diag([0.15**2] * 3 + [PRIOR[1] ** 2]))

    def run(retreat):
        world = _World([CENTRE])
        tracker = Tracker(cfg, CENTRE, PRIOR, filter_update("ekf", 10), visible)
        res = run_every_fruit(world, _NoView(), tracker, 4, 0.002, 3, zone=zone, retreat=retreat(world))
        return res, [v.p_world_camera.copy() for v in res.views]

    held, at = run(lambda world: None)
    assert all(np.array_equal(p, at[0]) for p in at)
    assert not any(e.kind == "retreated" for v in held.views for e in v.events)

    def back(world):
        def retreat(look_at):
            if world.p[0] < CENTRE[0] - 0.4:  # the aisle's edge: nothing farther back
                return None
            return ViewPlan(world.p - np.array([0.1, 0.0, 0.0]), look_at.copy(), "optimal", True, 0.0)

        return retreat

    res, at = run(back)
    xs = [p[0] for p in at]
    assert xs[1] < xs[0] and xs[2] < xs[1] and xs[3] == xs[2] == xs[4]  # two steps back, then held
    assert [any(e.kind == "retreated" for e in v.events) for v in res.views[1:]] == [True, True, False, False]
    assert all(v.plan_status == "fallback" for v in res.views[1:])


class _SeenPoorly(_World):
    """The first fruit as _World measures it; the second (behind its neighbours, in part in
    view) measured with a centre error of 40 px every view: a track that never localises."""

    def observe_all(self):
        out, model = super().observe_all()
        if len(out) < 2:
            return out, model
        poor = BearingSizeModel(model.p_world_camera, model.R_world_camera, np.eye(3) * (40.0 / F) ** 2)
        return [out[0], Sighting(out[1].z, poor)], model


def test_a_survey_that_stalls_on_a_hidden_fruit_ends_for_the_harvest_when_one_may_follow():
    """``SurveyRound.stall_views``: once a fruit is localised and that many views in a row localise no
    other while one is left unlocalised, the survey ends (``incomplete``) so that the harvest
    picks what is known first; without it, or when the fruit localised was visited by a
    harvest before, the survey goes on to its view budget. The views' directions land in
    ``explored``."""
    beside = CENTRE + np.array([0.0, 0.12, 0.0])

    def run(stall, explored=None, visited=()):
        cfg = TrackingConfig(fruits="all", zone_m=0.3)

        def visible(c, r, m):
            return visible_arc_deg(c, r, m.p_world_camera, m.R_world_camera, F, W, H) >= 150.0

        tracker = Tracker(cfg, CENTRE, PRIOR, filter_update("ekf", 10), visible)
        zone = Belief(np.r_[CENTRE, PRIOR[0]], np.diag([0.15**2] * 3 + [PRIOR[1] ** 2]))
        world = _SeenPoorly([CENTRE, beside])
        survey_round = SurveyRound(False, [] if explored is None else explored, stall, frozenset(visited))
        return run_every_fruit(world, _Planner(), tracker, 40, 0.002, 3, zone=zone, survey_round=survey_round)

    explored: list[np.ndarray] = []
    stalled = run(4, explored)
    assert stalled.outcome == Outcome.INCOMPLETE
    first = next(i for i, v in enumerate(stalled.views) if any(s.localised for s in v.fruits))
    assert len(stalled.views) == first + 5  # the view that localised it, then 4 with no other
    assert not all(s.localised for s in stalled.final)
    assert len(explored) == len(stalled.views)
    patient = run(0)
    assert len(patient.views) > len(stalled.views)
    # the fruit localised was visited by a harvest before (unreachable, say): nothing new to
    # pick, so the survey does not hand over
    localised = next(s.id for s in stalled.final if s.localised)
    assert len(run(4, visited={localised}).views) == len(patient.views)


def test_the_loop_tells_the_planner_which_views_the_tracks_misjudged_and_from_where():
    """A stem on one side (+y) hides the second fruit from every view there; the tracks, as
    spheres, predict it shows. Each such view is reported to a planner that learns where
    fruit hide (``note_hidden``), with the camera and the fruit's track: from that side only,
    for that fruit only; a planner that does not learn it is not asked."""
    beside = CENTRE + np.array([0.0, 0.1, 0.0])

    class _Stem(_World):
        def observe_all(self):
            R = camera_rotation(self.p, self.target)
            centres = np.array(self.fruit)
            seen = visible_arc_deg(centres, np.full(len(centres), RADIUS), self.p, R, F, W, H) >= 150.0
            seen[1] &= self.p[1] <= CENTRE[1] + 0.02  # the stem: the second fruit hidden from +y
            model = BearingSizeModel(self.p, R, np.eye(3) * (0.3 / F) ** 2)
            return [Sighting(model.predict(np.r_[c, RADIUS]), model) for c in centres[seen]], model

    class _Learns(_Planner):
        def __init__(self):
            super().__init__()
            self.hidden = []

        def note_hidden(self, fruit, p_world_camera, p_world_fruit):
            self.hidden.append((fruit, np.array(p_world_camera), np.array(p_world_fruit)))

    cfg = TrackingConfig(fruits="all", zone_m=0.3)

    def visible(c, r, m):
        return visible_arc_deg(c, r, m.p_world_camera, m.R_world_camera, F, W, H) >= 150.0

    planner = _Learns()
    tracker = Tracker(cfg, CENTRE, PRIOR, filter_update("ekf", 10), visible)
    zone = Belief(np.r_[CENTRE, PRIOR[0]], np.diag([0.15**2] * 3 + [PRIOR[1] ** 2]))
    res = run_every_fruit(_Stem([CENTRE, beside]), planner, tracker, 12, 0.002, 3, zone=zone)
    assert planner.hidden, "no view was reported"
    assert len({fruit for fruit, _, _ in planner.hidden}) == 1  # one track: the fruit behind the stem
    for _, camera, at in planner.hidden:
        assert camera[1] > CENTRE[1] + 0.02
        assert np.linalg.norm(at - beside) < 0.01
    assert run_every_fruit(_Stem([CENTRE, beside]), _Planner(), Tracker(cfg, CENTRE, PRIOR,
                           filter_update("ekf", 10), visible), 12, 0.002, 3, zone=zone).views  # fmt: skip
    assert res.views


def test_a_track_deleted_in_the_view_that_missed_it_is_not_reported_hidden():
    """A false detection seen in the first view only starts a track the later views predict
    to show and miss until it is deleted; in the view that deletes it, it was expected and
    not measured, but it is gone: the loop reports only live tracks (without that filter it
    asks the tracker for the deleted one and stops with a KeyError)."""
    ghost = CENTRE + np.array([0.0, -0.09, 0.05])

    class _Ghost(_World):
        views = 0

        def observe_all(self):
            out, model = super().observe_all()
            self.views += 1
            if self.views == 1:
                out = [*out, Sighting(model.predict(np.r_[ghost, RADIUS]), model)]
            return out, model

    class _Learns(_Planner):
        def __init__(self):
            super().__init__()
            self.hidden = []

        def plan(self, fruits, p_world_camera, iteration, q=None):  # always the real fruit
            return self._at(CENTRE), min(f.id for f in fruits)

        def note_hidden(self, fruit, p_world_camera, p_world_fruit):
            self.hidden.append(fruit)

    cfg = TrackingConfig(fruits="all", zone_m=0.3, explore_span_deg=0.0, zone_framed_share=0.0)

    def visible(c, r, m):
        return visible_arc_deg(c, r, m.p_world_camera, m.R_world_camera, F, W, H) >= 150.0

    planner = _Learns()
    tracker = Tracker(cfg, CENTRE, PRIOR, filter_update("ekf", 10), visible)
    zone = Belief(np.r_[CENTRE, PRIOR[0]], np.diag([0.15**2] * 3 + [PRIOR[1] ** 2]))
    res = run_every_fruit(_Ghost([CENTRE]), planner, tracker, 16, 0.002, 3, zone=zone)
    deleted = {e.track for v in res.views for e in v.tracking.events if e.kind == "deleted"}
    assert deleted, "the ghost's track was never deleted"
    last = next(v for v in res.views if any(e.kind == "deleted" for e in v.tracking.events))
    assert deleted <= set(last.tracking.expected)  # expected, missed and deleted in one view
    assert set(planner.hidden) & deleted  # its misses before the deletion were reported


def test_the_detected_share_follows_the_outline_shown_and_is_nil_below_the_detectors_arc():
    from bve_mj.planning.zone_coverage import DETECTED_BY_ARC, detected_share

    q = detected_share(np.array([0.0, 149.0, 150.0, 200.0, 359.0, 360.0]), 150.0)
    assert q[0] == 0.0 and q[1] == 0.0
    assert q[2] == DETECTED_BY_ARC[0][1] and q[-1] == DETECTED_BY_ARC[-1][1]
    assert q[-1] > q[3] > q[2] > 0.0  # a whole outline is measured more often than part of one
    assert detected_share(np.array([200.0]), 210.0)[0] == 0.0  # a stricter detector refuses it


def test_the_outline_past_a_known_fruit_is_none_behind_it_and_whole_beside_it():
    from bve_mj.planning.zone_coverage import outline_past

    p = CENTRE - np.array([0.3, 0.0, 0.0])
    R = camera_rotation(p, CENTRE)
    known = (CENTRE[None, :], np.array([RADIUS]))
    points = np.array([
        CENTRE + [0.065, 0.0, 0.0],  # right behind it, touching it: hidden
        CENTRE + [0.0, 0.08, 0.0],  # beside it: the whole outline
        CENTRE + [0.01, 0.0, 0.0],  # inside it: the known fruit holds the point
        CENTRE + [0.0, 0.0, 0.2],  # far above: no neighbour of it
    ])  # fmt: skip
    arc, occupied, near = outline_past(points, RADIUS, p, R, *known, F, W, H)
    assert arc[0] == 0.0 and arc[1] == 360.0
    assert list(occupied) == [False, False, True, False]
    assert list(near) == [True, True, True, False]
    none = outline_past(points, RADIUS, p, R, np.zeros((0, 3)), np.zeros(0), F, W, H)
    assert none[0][0] == 360.0 and not none[1].any() and not none[2].any()


def test_the_place_behind_a_known_fruit_is_framed_only_once_a_view_shows_past_it():
    """With the detector's arc, the neighbour's place right behind a known fruit seen from the
    front stays unframed until a view from the side shows a fruit there; the views before a
    fruit was known are counted again past it; without the arc, one image frames it."""
    behind = CENTRE + np.array([0.0625, 0.0, 0.0])
    front = CENTRE - np.array([0.3, 0.0, 0.0])
    side = CENTRE + np.array([0.05, -0.3, 0.0])
    known = (CENTRE[None, :], np.array([RADIUS]))
    strict = ZoneCoverage(CENTRE, 0.15, RADIUS, F, W, H, 0.8, min_arc_deg=150.0)
    strict.points_m = np.vstack([strict.points_m, behind])  # the place itself, on no grid node
    strict.framed = np.zeros(len(strict.points_m), dtype=bool)
    strict._counts_from = np.zeros(len(strict.points_m), dtype=int)
    strict.note(front, camera_rotation(front, CENTRE))  # nothing known yet: a clear view
    assert strict.framed[-1]
    strict.note(front, camera_rotation(front, CENTRE), known)  # the fruit found: hidden behind it
    assert not strict.framed[-1]
    strict.note(side, camera_rotation(side, CENTRE), known)
    assert strict.framed[-1]
    loose = _coverage()
    loose.points_m = np.vstack([loose.points_m, behind])
    loose.framed = np.zeros(len(loose.points_m), dtype=bool)
    loose._counts_from = np.zeros(len(loose.points_m), dtype=int)
    loose.note(front, camera_rotation(front, CENTRE), known)
    assert loose.framed[-1]
