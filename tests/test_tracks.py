"""Tracks of every fruit: a track from one detection, the optimal assignment, the tracker's
life cycle on synthetic views of trusses, and the visibility predicted from the tracks."""

import itertools
import math

import numpy as np
import pytest

from bve_mj.config import TrackingConfig
from bve_mj.estimation import BearingSizeModel, Belief, filter_update
from bve_mj.estimation.tracks import Sighting, Tracker, assign, belief_from_detection
from bve_mj.estimation.visibility import visible_arc_deg
from bve_mj.geometry import camera_rotation

F, W, H = 466.0, 640, 480
SIGMA_PX = 0.4
UPDATE = filter_update("ekf", 10)
CONFIRM = TrackingConfig().confirm_hits


def _z(centre, radius, p, R):
    t = R.T @ (np.asarray(centre) - p)
    return np.array([t[1] / t[0], t[2] / t[0], math.asin(radius / np.linalg.norm(t))])


def _model(p, R, sigma_px=SIGMA_PX):
    return BearingSizeModel(p, R, np.eye(3) * (sigma_px / F) ** 2)


def _visible(min_arc=150.0):
    def visible(centres, radii, model):
        arcs = visible_arc_deg(centres, radii, model.p_world_camera, model.R_world_camera, F, W, H)
        return arcs >= min_arc

    return visible


def _truss(n, rng, radius=0.03):
    """n touching fruit along a bending chain, centred near (0.5, 0, 0.3)."""
    centres = [np.array([0.5, 0.0, 0.3])]
    heading = np.array([0.0, 1.0, -0.3])
    for _ in range(n - 1):
        heading = heading + rng.normal(0.0, 0.3, 3) * np.array([0.3, 1.0, 1.0])
        heading /= np.linalg.norm(heading)
        centres.append(centres[-1] + 2.02 * radius * heading)
    c = np.array(centres)
    c -= c.mean(axis=0) - np.array([0.5, 0.0, 0.3])
    return c, np.full(n, radius) * rng.uniform(0.9, 1.1, n)


def _views(k):
    """k camera positions on an arc 0.3 m in front of the truss (robot side, -x), looking at it."""
    out = []
    for i in range(k):
        a = math.radians(-40.0 + 80.0 * i / max(k - 1, 1))
        el = math.radians(15.0 * math.sin(2.1 * i))
        d = np.array([-math.cos(el) * math.cos(a), math.cos(el) * math.sin(a), math.sin(el)])
        p = np.array([0.5, 0.0, 0.3]) + 0.3 * d
        out.append((p, camera_rotation(p, np.array([0.5, 0.0, 0.3]))))
    return out


def test_a_track_from_one_detection_projects_back_and_its_covariance_is_the_propagated_one(rng):
    p = np.array([0.0, 0.1, 0.3])
    centre, r = np.array([0.3, 0.05, 0.35]), 0.031
    R = camera_rotation(p, centre + np.array([0.0, 0.02, -0.01]))
    s = Sighting(_z(centre, r, p, R), _model(p, R))
    b = belief_from_detection(s, 0.03, 0.003)
    assert np.allclose(s.model.predict(b.mean), s.z, atol=1e-12)
    assert b.radius_m == pytest.approx(0.03)
    # Monte Carlo of the inverse measurement: (u, v, α, r) → (centre, r)
    n = 40_000
    zs = s.z + rng.normal(0.0, SIGMA_PX / F, (n, 3))
    rs = 0.03 + rng.normal(0.0, 0.003, n)
    rays = np.column_stack([np.ones(n), zs[:, 0], zs[:, 1]])
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    cs = p + (rs / np.sin(zs[:, 2]))[:, None] * (rays @ R.T)
    emp = np.cov(np.column_stack([cs, rs]).T)
    sd = np.sqrt(np.diag(b.cov))
    assert np.allclose(np.sqrt(np.diag(emp)), sd, rtol=0.05)
    corr = b.cov / np.outer(sd, sd)
    assert np.allclose(emp / np.outer(np.sqrt(np.diag(emp)), np.sqrt(np.diag(emp))), corr, atol=0.03)


def test_a_bad_detection_starts_no_track():
    p, R = np.zeros(3), np.eye(3)
    with pytest.raises(Exception, match="starts from a detection"):
        belief_from_detection(Sighting(np.array([0.0, 0.0, -0.1]), _model(p, R)), 0.03, 0.003)


def test_the_assignment_is_the_brute_force_optimum(rng):
    p = np.zeros(3)
    R = camera_rotation(p, np.array([0.4, 0.0, 0.0]))
    for trial in range(20):
        n = int(rng.integers(2, 6))
        centres = np.array([0.4, 0.0, 0.0]) + rng.normal(0.0, 0.03, (n, 3))
        beliefs = [
            Belief(np.r_[c + rng.normal(0, 0.003, 3), 0.03], np.diag([1e-5] * 3 + [1e-6])) for c in centres
        ]
        sightings = [Sighting(_z(c, 0.03, p, R) + rng.normal(0, 1e-3, 3), _model(p, R, 2.0)) for c in centres]
        sightings = [sightings[k] for k in rng.permutation(n)][: n - trial % 2]  # sometimes one short
        pairs, nis = assign(beliefs, sightings, 0.9999)
        cost = np.array([[nis[i, j] for j in range(len(sightings))] for i in range(n)])
        logdet = np.zeros_like(cost)
        for i, j in itertools.product(range(n), range(len(sightings))):
            Hm = sightings[j].model.jacobian(beliefs[i].mean)
            S = Hm @ beliefs[i].cov @ Hm.T + sightings[j].model.noise_cov
            logdet[i, j] = np.linalg.slogdet(S)[1]
        gate = 21.1  # χ²₃(0.9999)
        best = math.inf
        for perm in itertools.permutations(range(n), len(sightings)):
            pairs_b = [(i, j) for j, i in enumerate(perm) if cost[i, j] <= gate]
            # the optimum takes every allowed pair it can (unassigned pairs cost "big")
            total = sum(cost[i, j] + logdet[i, j] for i, j in pairs_b) + 1e9 * (len(sightings) - len(pairs_b))
            best = min(best, total)
        got = sum(cost[i, j] + logdet[i, j] for i, j in pairs) + 1e9 * (len(sightings) - len(pairs))
        assert got == pytest.approx(best, rel=1e-9, abs=1e-6)


@pytest.mark.parametrize("state", [4, 7])
def test_the_batched_innovations_are_each_pairs_own(rng, state):
    """The association's NIS matrix, each track's prediction made once per view and the pairs
    factored in one batch, is each pair's own (to 1e-12), for tracks with and without the
    camera's biases, sightings of different noise, and sightings from two poses (then pair by
    pair)."""
    from bve_mj.estimation.assignment import _innovations, _pair_by_pair

    p = np.zeros(3)
    R = camera_rotation(p, np.array([0.4, 0.0, 0.0]))
    for trial in range(10):
        n, m = int(rng.integers(1, 8)), int(rng.integers(1, 8))
        centres = np.array([0.4, 0.0, 0.0]) + rng.normal(0.0, 0.04, (n, 3))
        beliefs = []
        for c in centres:
            A = rng.normal(size=(state, state)) * 1e-3
            beliefs.append(Belief(np.r_[c, 0.03, np.zeros(state - 4)], A @ A.T + np.eye(state) * 1e-7))
        sightings = [
            Sighting(_z(c, 0.03, p, R) + rng.normal(0, 2e-3, 3), _model(p, R, rng.uniform(0.3, 5.0)))
            for c in np.array([0.4, 0.0, 0.0]) + rng.normal(0.0, 0.04, (m, 3))
        ]
        if trial % 3 == 2:  # another pose for one of them
            q = np.array([0.0, 0.05, 0.0])
            sightings[0] = Sighting(sightings[0].z, _model(q, camera_rotation(q, centres[0]), 1.0))
        got, ref = _innovations(beliefs, sightings), _pair_by_pair(beliefs, sightings)
        for a, b in zip(got, ref, strict=True):
            np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)


def _run_tracker(n_fruit, seed, views=8, drop_p=0.2, false_views=(2, 5)):
    rng = np.random.default_rng(seed)
    centres, radii = _truss(n_fruit, rng)
    cfg = TrackingConfig(fruits="all", zone_m=0.25, confirm_hits=CONFIRM)
    tracker = Tracker(cfg, centres.mean(axis=0), (0.03, 0.003), UPDATE, _visible())
    history: dict[int, set[int]] = {}  # fruit -> track ids ever assigned its detections
    false_ids: list[int] = []
    for v, (p, R) in enumerate(_views(views)):
        arcs = visible_arc_deg(centres, radii, p, R, F, W, H)
        sightings, owner = [], []
        for k in range(n_fruit):
            if arcs[k] >= 150.0 and rng.random() > drop_p:
                z = _z(centres[k], radii[k], p, R) + rng.normal(0.0, SIGMA_PX / F, 3)
                sightings.append(Sighting(z, _model(p, R)))
                owner.append(k)
        if v in false_views:  # something red 5-10 cm off the truss, seen once
            fake = centres.mean(axis=0) + rng.choice([-1, 1], 3) * rng.uniform(0.05, 0.1, 3) * [0.3, 1, 1]
            sightings.append(Sighting(_z(fake, 0.03, p, R), _model(p, R)))
            owner.append(-1)
        # the view is planned for the least certain track (as the every-fruit planner does)
        worst = max(tracker.tracks, key=lambda t: t.belief.sigma_max_m, default=None)
        step = tracker.step(sightings, _model(p, R), v, None if worst is None else worst.id)
        for j, tid in step.assigned:
            if owner[j] >= 0:
                history.setdefault(owner[j], set()).add(tid)
            else:
                false_ids.append(tid)
        for j, tid in step.started:
            if owner[j] >= 0:
                history.setdefault(owner[j], set()).add(tid)
            else:
                false_ids.append((v, tid))
    return tracker, centres, radii, history, false_ids


@pytest.mark.parametrize("n_fruit", [2, 4, 6, 8])
def test_every_fruit_of_a_truss_is_tracked_without_swaps_and_a_false_detection_is_never_confirmed(n_fruit):
    for seed in range(3):
        tracker, centres, _radii, history, false_ids = _run_tracker(n_fruit, seed)
        confirmed = tracker.confirmed
        # each confirmed track lies on one true fruit (within 5 mm), each fruit has one
        matched = []
        for t in confirmed:
            d = np.linalg.norm(centres - t.centre_m, axis=1)
            k = int(np.argmin(d))
            assert d[k] < 0.005, f"seed {seed}: confirmed track {t.id} is {1e3 * d[k]:.1f} mm from any fruit"
            matched.append(k)
        assert len(matched) == len(set(matched)), f"seed {seed}: two confirmed tracks on one fruit"
        seen_twice = [k for k in range(n_fruit) if k in history]
        assert set(matched) >= {k for k in seen_twice if len(history[k]) >= 1 and k in matched}
        # no swap: the detections of each fruit went to one track (a track merged away aside)
        for k, ids in history.items():
            alive = [i for i in ids if any(t.id == i for t in tracker.tracks)]
            assert len(alive) <= 1, f"seed {seed}: fruit {k}'s detections feed tracks {sorted(ids)}"
        # fruit seen at least confirm_hits times are confirmed
        for k, ids in history.items():
            hits = sum(t.hits for t in tracker.tracks if t.id in ids)
            if hits >= CONFIRM:
                assert k in matched, f"seed {seed}: fruit {k} seen {hits} times has no confirmed track"
        # the false detections: never confirmed
        assert false_ids, "the false detections were never seen by the tracker"
        for _, tid in false_ids:
            assert all(t.id != tid or not t.confirmed for t in tracker.tracks), (
                f"seed {seed}: {tid} confirmed"
            )


def test_a_detection_never_seen_again_is_deleted_after_the_views_planned_for_it():
    fruit = np.array([0.45, 0.0, 0.3])
    cfg = TrackingConfig(fruits="all", zone_m=0.2, delete_misses=2)
    tracker = Tracker(cfg, fruit, (0.03, 0.003), UPDATE, _visible())
    views = _views(9)
    p, R = views[0]
    tracker.step([Sighting(_z(fruit, 0.03, p, R), _model(p, R))], _model(p, R), 0)
    (tid,) = [t.id for t in tracker.tracks]
    # views planned for other things that should have seen it: up to 3 x delete_misses - 1 kept
    for v in range(1, 6):
        p, R = views[v]
        tracker.step([], _model(p, R), v, planned_for=None)
    assert [t.id for t in tracker.tracks] == [tid] and tracker.track(tid).misses == 5
    p, R = views[6]
    tracker.step([], _model(p, R), 6, planned_for=None)
    assert tracker.tracks == [], "six misses did not delete a track seen once"
    # a fresh one: two views planned for it that miss it delete it
    p, R = views[7]
    tracker.step([Sighting(_z(fruit, 0.03, p, R), _model(p, R))], _model(p, R), 7)
    (tid,) = [t.id for t in tracker.tracks]
    for v in (8, 0):
        p, R = views[v]
        tracker.step([], _model(p, R), 9 + v, planned_for=tid)
    assert tracker.tracks == []


def test_views_planned_for_a_track_of_one_viewpoint_count_even_where_it_is_predicted_out_of_view():
    """From one viewpoint a track's place along its ray is unknown, so is whether a view
    should see it: each view planned for it that misses it counts (``ripe_truss`` 601185105
    planned 5 of 16 views for one, two of them predicted not to see its mean). A track two
    viewpoints place (triangulated) counts only the views predicted to see it."""
    fruit = np.array([0.45, 0.0, 0.3])
    cfg = TrackingConfig(fruits="all", zone_m=0.2, delete_misses=2)
    views = _views(9)
    p_away = np.array([0.45, 0.6, 0.3])  # beside the fruit, looking away from it
    R_away = camera_rotation(p_away, p_away + np.array([0.0, 1.0, 0.0]))
    tracker = Tracker(cfg, fruit, (0.03, 0.003), UPDATE, _visible())
    p, R = views[0]
    tracker.step([Sighting(_z(fruit, 0.03, p, R), _model(p, R))], _model(p, R), 0)
    (track,) = tracker.tracks
    assert not tracker.predicted_visible(_model(p_away, R_away))[0]
    tracker.step([], _model(p_away, R_away), 1, planned_for=track.id)
    assert track.failed == 1 and track.misses == 0
    tracker.step([], _model(p_away, R_away), 2, planned_for=track.id)
    assert tracker.tracks == [] and tracker.dropped == [track]
    # two viewpoints: a view planned for it that could not see it is no evidence
    tracker = Tracker(cfg, fruit, (0.03, 0.003), UPDATE, _visible())
    for v in (0, 8):
        p, R = views[v]
        tracker.step([Sighting(_z(fruit, 0.03, p, R), _model(p, R))], _model(p, R), v)
    (track,) = tracker.tracks
    tracker.step([], _model(p_away, R_away), 9, planned_for=track.id)
    assert track.failed == 0


def test_a_known_fruit_mismeasured_starts_no_track_and_a_neighbour_does():
    """A detection of a confirmed fruit placed to within its radius, its outline fitted a fifth
    of a radius off (a part hidden) and outside the track's gate, is that fruit mismeasured:
    ignored, no new track (a tentative one's starts a track). A detection of a touching
    neighbour, two radii off in the image, starts one."""
    fruit, r = np.array([0.45, 0.0, 0.3]), 0.03
    views = _views(9)
    p, R = views[2]
    z = _z(fruit, r, p, R)
    off = z + np.array([0.2 * math.tan(z[2]), 0.0, 0.0])  # a fifth of its apparent radius aside
    for confirming in ((), (4,)):
        tracker = Tracker(TrackingConfig(fruits="all", zone_m=0.2), fruit, (r, 0.003), UPDATE, _visible())
        for v in (0, 8, *confirming):
            q, Rq = views[v]
            tracker.step([Sighting(_z(fruit, r, q, Rq), _model(q, Rq))], _model(q, Rq), v)
        (track,) = tracker.tracks
        assert track.triangulated and track.confirmed == bool(confirming)
        if not confirming:  # two viewpoints may place it wrong: the detection starts a track
            assert len(tracker.step([Sighting(off, _model(p, R))], _model(p, R), 10).started) == 1
    step = tracker.step([Sighting(off, _model(p, R))], _model(p, R), 10)
    assert step.assigned == () and step.started == () and step.ignored == (0,)
    assert tracker.tracks == [track]
    neighbour = fruit + 2.02 * r * np.array([0.0, 1.0, 0.0])
    step = tracker.step([Sighting(_z(neighbour, r, p, R), _model(p, R))], _model(p, R), 11)
    assert len(step.started) == 1 and len(tracker.tracks) == 2


def test_a_fruit_two_views_place_to_within_its_radius_is_kept_through_misses_until_confirmed():
    """A tentative track from two views whose rays cross at the fruit (3σmax ≤ r̂) is not
    deleted by the misses that delete a track of one view (the detector refuses a fruit
    behind its neighbours from most views); a third view confirms it."""
    fruit = np.array([0.45, 0.0, 0.3])
    cfg = TrackingConfig(fruits="all", zone_m=0.2, delete_misses=2)
    tracker = Tracker(cfg, fruit, (0.03, 0.003), UPDATE, _visible())
    views = _views(9)
    for v in (0, 8):  # 80 degrees apart
        p, R = views[v]
        tracker.step([Sighting(_z(fruit, 0.03, p, R), _model(p, R))], _model(p, R), v)
    (track,) = tracker.tracks
    assert not track.confirmed and track.triangulated
    assert 3.0 * track.belief.sigma_max_m <= track.radius_m
    for v in range(1, 8):  # planned for it, every one misses it: 7 > 3 x delete_misses
        p, R = views[v]
        tracker.step([], _model(p, R), 10 + v, planned_for=track.id)
    assert tracker.tracks == [track] and track.failed == 7
    p, R = views[4]
    tracker.step([Sighting(_z(fruit, 0.03, p, R), _model(p, R))], _model(p, R), 20)
    assert track.confirmed and float(np.linalg.norm(track.centre_m - fruit)) < 1e-3


def test_views_of_a_held_camera_are_one_viewpoint_and_do_not_confirm_a_track():
    """A camera held where it was (its planner finding no move) sees what it saw: three
    detections from it are one viewpoint, the track stays tentative (and is not
    triangulated: one ray); detections from two more viewpoints confirm it."""
    fruit = np.array([0.45, 0.0, 0.3])
    tracker = Tracker(TrackingConfig(fruits="all", zone_m=0.2), fruit, (0.03, 0.003), UPDATE, _visible())
    views = _views(9)
    p, R = views[2]
    for v in range(3):
        held = p + np.array([0.0, 0.0, 1e-4 * v])  # the encoders' jitter
        tracker.step([Sighting(_z(fruit, 0.03, held, R), _model(held, R))], _model(held, R), v)
    (track,) = tracker.tracks
    assert track.hits == 3 and len(track.views) == 3 and len(track.viewpoints) == 1
    assert not track.confirmed and not track.triangulated
    for v in (5, 8):
        p, R = views[v]
        tracker.step([Sighting(_z(fruit, 0.03, p, R), _model(p, R))], _model(p, R), v)
    assert track.confirmed and len(track.viewpoints) == 3


def test_a_held_camera_adds_to_a_track_only_the_share_its_repeats_hold():
    """The tracker fuses a view as the share it adds beside the track's views, the cameras'
    places counted (:mod:`bve_mj.estimation.view_correlation`): three more sightings from the
    camera held where it was (the encoders' jitter apart) shrink the track's covariance only
    a little, where counted by their directions alone they would shrink it by half a fresh
    view's worth each; the track keeps each view's camera position."""
    from bve_mj.estimation.view_correlation import ViewCorrelation

    by_place = (ViewCorrelation(0.3, 0.03, 0.85, 0.01), ViewCorrelation(0.35, 0.12, 0.83, 0.014))
    by_direction = tuple(ViewCorrelation(c.weight, c.width) for c in by_place)
    fruit = np.array([0.45, 0.0, 0.3])
    p, R = _views(9)[4]
    shrunk = []
    for corr in (by_place, by_direction):
        cfg = TrackingConfig(fruits="all", zone_m=0.2)
        tracker = Tracker(cfg, fruit, (0.03, 0.003), UPDATE, _visible(), correlation=corr)
        volumes = []
        for v in range(4):
            at = p + np.array([0.0, 1e-4 * v, 0.0])
            tracker.step([Sighting(_z(fruit, 0.03, at, R), _model(at, R))], _model(at, R), v)
            volumes.append(np.linalg.det(tracker.tracks[0].belief.cov[:3, :3]))
        (track,) = tracker.tracks
        assert len(track.cameras) == len(track.directions) == 4
        shrunk.append(volumes[-1] / volumes[0])
    assert shrunk[0] > 0.7 and shrunk[1] < 0.3  # ~(1 + 3Δ)^-k: Δ ≈ 0.07 held, 0.5 by direction


def test_two_sightings_of_one_fruit_from_far_apart_views_make_one_track():
    """Two tentative tracks of one fruit cross at it: merged into one (confirmed) track whose
    belief is their information added (the radius prior once)."""
    fruit, r = np.array([0.45, 0.02, 0.3]), 0.027
    cfg = TrackingConfig(fruits="all", zone_m=0.2, gate_probability=1e-6, confirm_hits=2)  # gate shut
    tracker = Tracker(cfg, fruit, (0.03, 0.003), UPDATE, _visible())
    (p0, R0), (p1, R1) = _views(5)[0], _views(5)[4]
    s0 = Sighting(_z(fruit, r, p0, R0), _model(p0, R0))
    s1 = Sighting(_z(fruit, r, p1, R1), _model(p1, R1))
    tracker.step([s0], _model(p0, R0), 0)
    step = tracker.step([s1], _model(p1, R1), 1)
    assert [e.kind for e in step.events if e.kind == "merged"] == ["merged"]
    (t,) = tracker.tracks
    assert t.confirmed and t.hits == 2
    assert np.linalg.norm(t.centre_m - fruit) < 1e-4 and abs(t.radius_m - r) < 2e-4
    # the same as fusing the second sighting into the first track
    direct = UPDATE(belief_from_detection(s0, 0.03, 0.003), s1.z, s1.model, None).belief
    assert np.allclose(t.belief.mean, direct.mean, atol=2e-5)
    # (each linearised at its own ray: within 10% of the sequential update's σ)
    assert np.allclose(np.sqrt(np.diag(t.belief.cov)), np.sqrt(np.diag(direct.cov)), rtol=0.1)


def test_two_tracks_of_one_fruit_that_disagree_merge_into_their_fused_belief_widened():
    """Two sightings of one fruit from two views, biased 3 mm below, then above, their rays (a
    part of the fruit hidden: more than their 0.4 px allow), start two tracks too far apart in
    χ² to agree yet closer than half a radius: one fruit. Their fused belief, widened by χ²/4,
    holds the fruit within 3σ (``ripe_truss`` 4132417405 of seed 1357 kept one of them, 20 mm
    along its ray, and spent ten views on it: its detections never fell in its gate)."""
    fruit, r = np.array([0.45, 0.02, 0.3]), 0.03
    cfg = TrackingConfig(fruits="all", zone_m=0.2, gate_probability=1e-6, confirm_hits=2)  # gate shut
    tracker = Tracker(cfg, fruit, (0.03, 0.003), UPDATE, _visible())
    for view, k in enumerate((0, 2)):
        p, R = _views(5)[k]
        off = 0.003 * R[:, 2] * (1.0 if view else -1.0)  # the rays pass 6 mm apart: no point on both
        step = tracker.step([Sighting(_z(fruit + off, r, p, R), _model(p, R))], _model(p, R), view)
    (t,) = tracker.tracks
    assert [e.kind for e in step.events if e.kind != "missed"] == ["started", "merged"]
    assert t.confirmed and t.hits == 2
    err = t.centre_m - fruit
    assert float(err @ np.linalg.solve(t.belief.cov[:3, :3], err)) <= 14.2  # inside 3σ
    assert 0.001 < t.belief.sigma_max_m < 0.01  # placed (each alone: 28 mm along its ray), not to 0.3 mm


def test_forgotten_tracks_leave_by_identity_and_are_not_counted_as_dropped():
    """``Tracker.forget`` removes exactly the tracks given (others stay, in order, with their
    state), and none of them is counted as deleted for misses; with no argument, every one."""
    c, r = _truss(3, np.random.default_rng(4))
    tracker = Tracker(
        TrackingConfig(fruits="all", zone_m=0.3), c.mean(axis=0), (0.03, 0.003), UPDATE, _visible()
    )
    p, R = _views(3)[1]
    tracker.step(
        [Sighting(_z(ci, ri, p, R), _model(p, R)) for ci, ri in zip(c, r, strict=True)], _model(p, R), 0
    )
    a, b, d = tracker.tracks
    tracker.forget([b])
    assert tracker.tracks == [a, d] and tracker.tracks[0] is a and not tracker.dropped
    tracker.forget([])
    assert tracker.tracks == [a, d]
    tracker.forget()
    assert tracker.tracks == [] and not tracker.dropped


def test_two_things_in_one_image_never_merge_by_agreement_nor_confirm_each_other():
    """Two sightings of one view (two fragments of a fruit, or two fruit side by side): their
    rays leave one camera and agree near it, crossing nowhere. Seen again from the same pose,
    they stay two tentative tracks of two views each (merged by agreement, they became one
    track of three detections from two views, confirmed when hits counted detections)."""
    centre = np.array([0.45, 0.0, 0.3])
    cfg = TrackingConfig(fruits="all", zone_m=0.2, gate_probability=1e-6, confirm_hits=3)  # gate shut
    tracker = Tracker(cfg, centre, (0.03, 0.003), UPDATE, _visible())
    p, R = _views(5)[2]
    wide = lambda: BearingSizeModel(p, R, np.diag([(8.0 / F) ** 2] * 2 + [0.2**2]))  # noqa: E731
    a, b = centre + np.array([0.0, 0.035, 0.0]), centre - np.array([0.0, 0.035, 0.0])  # two touching fruit
    for view in range(2):
        step = tracker.step(
            [Sighting(_z(a, 0.03, p, R), wide()), Sighting(_z(b, 0.03, p, R), wide())], wide(), view
        )
        assert not [e for e in step.events if e.kind == "merged"]
    assert len(tracker.tracks) == 2 and not any(t.confirmed for t in tracker.tracks)
    assert all(t.views == {0, 1} and t.hits == 2 for t in tracker.tracks)


def test_without_its_gate_a_detection_would_be_given_to_the_wrong_fruit():
    """Break the gate on purpose: with every pair allowed, a lone detection of a new fruit is
    assigned to a far track instead of starting its own (the test above relies on the gate)."""
    p = np.zeros(3)
    R = camera_rotation(p, np.array([0.4, 0.0, 0.0]))
    a = Belief(np.array([0.4, 0.0, 0.0, 0.03]), np.diag([1e-6] * 3 + [1e-7]))
    s = Sighting(_z(np.array([0.4, 0.1, 0.0]), 0.03, p, R), _model(p, R))
    assert assign([a], [s], 0.9999)[0] == []
    assert assign([a], [s], 1.0 - 1e-300)[0] == [(0, 0)]


def test_a_fruit_behind_a_nearer_one_is_predicted_hidden_and_visible_from_the_side():
    front = np.array([0.40, 0.0, 0.3])
    back = np.array([0.47, 0.0, 0.3])  # 7 cm behind it along the line of sight
    centres, radii = np.array([front, back]), np.array([0.032, 0.03])
    p = np.array([0.1, 0.0, 0.3])
    R = camera_rotation(p, back)
    arcs = visible_arc_deg(centres, radii, p, R, F, W, H)
    assert arcs[0] == pytest.approx(360.0)
    assert arcs[1] == 0.0
    p_side = np.array([0.43, -0.3, 0.3])  # from the side: both show most of their outline
    arcs = visible_arc_deg(centres, radii, p_side, camera_rotation(p_side, back), F, W, H)
    assert arcs[0] >= 250.0 and arcs[1] >= 250.0
    # outside the image: nothing
    p_away = np.array([0.1, 0.0, 0.3])
    arcs = visible_arc_deg(centres, radii, p_away, camera_rotation(p_away, p_away + [0, 1, 0]), F, W, H)
    assert np.all(arcs == 0.0)


def test_with_rims_only_a_nearer_fruit_hides_an_outline():
    """Two touching fruit seen obliquely overlap in the image. Without rims the shared stretch
    is nobody's outline; with rims (the detector's interior edges) the nearer fruit keeps its
    whole outline and only the farther one loses the stretch behind it."""
    near, far = np.array([0.40, 0.0, 0.3]), np.array([0.44, 0.045, 0.3])  # 6 cm apart: touching
    centres, radii = np.array([near, far]), np.array([0.03, 0.03])
    p = np.array([0.1, 0.0, 0.3])
    R = camera_rotation(p, (near + far) / 2)
    plain = visible_arc_deg(centres, radii, p, R, F, W, H)
    rims = visible_arc_deg(centres, radii, p, R, F, W, H, rims=True)
    assert plain[0] < 300.0 and plain[1] < 300.0  # the overlap takes both outlines
    assert rims[0] == pytest.approx(360.0)
    assert rims[1] == pytest.approx(plain[1])
    # swap which is nearer: the answer follows the depth, not the order
    p_back = np.array([0.74, 0.045, 0.3])
    rims = visible_arc_deg(
        centres, radii, p_back, camera_rotation(p_back, (near + far) / 2), F, W, H, rims=True
    )
    assert rims[1] == pytest.approx(360.0) and rims[0] < 300.0


def test_the_tracker_does_not_count_a_hidden_fruit_as_missed():
    front, back = np.array([0.40, 0.0, 0.3]), np.array([0.47, 0.0, 0.3])
    cfg = TrackingConfig(fruits="all", zone_m=0.2, delete_misses=1)
    tracker = Tracker(cfg, front, (0.03, 0.003), UPDATE, _visible())
    side = np.array([0.43, -0.3, 0.3])
    R = camera_rotation(side, back)
    tracker.step([Sighting(_z(c, 0.03, side, R), _model(side, R)) for c in (front, back)], _model(side, R), 0)
    assert len(tracker.tracks) == 2
    p = np.array([0.1, 0.0, 0.3])
    R = camera_rotation(p, back)
    step = tracker.step([Sighting(_z(front, 0.03, p, R), _model(p, R))], _model(p, R), 1)
    assert len(tracker.tracks) == 2, "the hidden fruit's tentative track was deleted as missed"
    assert len(step.expected) == 1


PP_SIGMA, FOCAL_SIGMA = 2.0 / F, 0.01  # the realistic sensors' principal point (2 px) and focal (1%)
BIAS_SIGMAS = (PP_SIGMA, PP_SIGMA, FOCAL_SIGMA)


def test_a_track_that_carries_the_camera_biases_starts_from_the_propagated_covariance(rng):
    """With the calibration biases in the state (7,), a detection's track puts the centre on the
    ray as before, the biases at 0, and the covariance of the inverse measurement with the
    biases drawn too: the camera measured ((u + δy)/(1 + ε), (v + δz)/(1 + ε), atan(tan α/(1 + ε)))."""
    p = np.array([0.0, 0.1, 0.3])
    centre, r = np.array([0.3, 0.05, 0.35]), 0.031
    R = camera_rotation(p, centre + np.array([0.0, 0.04, -0.02]))
    s = Sighting(_z(centre, r, p, R), _model(p, R))
    b = belief_from_detection(s, 0.03, 0.003, BIAS_SIGMAS)
    assert b.dim == 7 and np.allclose(b.mean[4:], 0.0)
    assert np.allclose(s.model.predict(b.mean), s.z, atol=1e-12)
    assert np.allclose(b.mean[:4], belief_from_detection(s, 0.03, 0.003).mean)
    n = 60_000
    zs = s.z + rng.normal(0.0, SIGMA_PX / F, (n, 3))
    rs = 0.03 + rng.normal(0.0, 0.003, n)
    bias = rng.normal(0.0, 1.0, (n, 3)) * np.array(BIAS_SIGMAS)
    u = zs[:, 0] * (1.0 + bias[:, 2]) - bias[:, 0]
    v = zs[:, 1] * (1.0 + bias[:, 2]) - bias[:, 1]
    alpha = np.arctan(np.tan(zs[:, 2]) * (1.0 + bias[:, 2]))
    rays = np.column_stack([np.ones(n), u, v])
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    cs = p + (rs / np.sin(alpha))[:, None] * (rays @ R.T)
    emp = np.cov(np.column_stack([cs, rs, bias]).T)
    sd, emp_sd = np.sqrt(np.diag(b.cov)), np.sqrt(np.diag(emp))
    assert np.allclose(emp_sd, sd, rtol=0.05)
    assert np.allclose(emp / np.outer(emp_sd, emp_sd), b.cov / np.outer(sd, sd), atol=0.03)
    with pytest.raises(Exception, match="calibration sigmas"):
        belief_from_detection(s, 0.03, 0.003, (PP_SIGMA, 0.0, FOCAL_SIGMA))


def test_two_tracks_that_carry_the_biases_merge_with_the_prior_counted_once():
    from bve_mj.estimation.track_merge import fused_belief

    rng = np.random.default_rng(3)
    prior = np.zeros((7, 7))
    prior[3, 3] = 1.0 / 0.003**2
    prior[4:, 4:] = np.diag(1.0 / np.square(BIAS_SIGMAS))
    scale = np.diag([1e3, 1e3, 1e3, 1e3, 1e2, 1e2, 10.0])
    A = rng.normal(0.0, 1.0, (7, 7)) @ scale
    b = Belief(np.r_[0.4, 0.01, 0.0, 0.03, 1e-3, -1e-3, 0.005], np.linalg.inv(prior + A.T @ A))
    fused = fused_belief(b, b, (0.03, 0.003), BIAS_SIGMAS)
    assert fused is not None
    info = np.linalg.inv(fused.cov)
    assert np.allclose(info, 2.0 * np.linalg.inv(b.cov) - prior, rtol=1e-6, atol=1e-6 * np.abs(info).max())
    # the mean: both tracks' information about it, less the prior's (at r0 and zero biases)
    prior_mean = np.r_[0.0, 0.0, 0.0, 0.03, 0.0, 0.0, 0.0]
    expect = np.linalg.solve(info, 2.0 * np.linalg.solve(b.cov, b.mean) - prior @ prior_mean)
    assert np.allclose(fused.mean, expect, atol=1e-9)


def _biased_truss_nees(seed, calibration_sigmas):
    """The confirmed tracks' centre NEES after 8 views of a five-fruit truss by a camera whose
    principal point and focal length are off by a draw of the realistic sensors' errors."""
    rng = np.random.default_rng(seed)
    centres, radii = _truss(5, rng)
    bias = rng.normal(0.0, 1.0, 3) * np.array(BIAS_SIGMAS)
    cfg = TrackingConfig(fruits="all", zone_m=0.25, confirm_hits=CONFIRM)
    tracker = Tracker(cfg, centres.mean(axis=0), (0.03, 0.003), UPDATE, _visible(), None, calibration_sigmas)
    for v, (p, R) in enumerate(_views(8)):
        arcs = visible_arc_deg(centres, radii, p, R, F, W, H)
        sightings = [
            Sighting(
                _model(p, R).predict(np.r_[centres[k], radii[k], bias]) + rng.normal(0.0, SIGMA_PX / F, 3),
                _model(p, R),
            )
            for k in range(len(centres))
            if arcs[k] >= 150.0
        ]
        tracker.step(sightings, _model(p, R), v, None)
    nees = []
    for t in tracker.confirmed:
        d = t.centre_m - centres[int(np.argmin(np.linalg.norm(centres - t.centre_m, axis=1)))]
        nees.append(float(d @ np.linalg.solve(t.belief.cov[:3, :3], d)))
    return nees


def test_tracks_that_carry_the_camera_biases_claim_what_a_biased_camera_gives():
    """A camera whose calibration is off (2 px principal point, 1% focal: the realistic
    sensors) shifts every detection the same way: tracks that leave the biases out of their
    state claim a tenth of a millimetre hundreds of σ off; carrying them (7,), as the
    one-target filter does, their centre NEES is honest (3 on average: 2.998 over 150 fruit)."""
    without = [x for seed in range(10) for x in _biased_truss_nees(seed, None)]
    carried = [x for seed in range(30) for x in _biased_truss_nees(seed, BIAS_SIGMAS)]
    assert len(carried) >= 120 and np.mean(np.array(without) > 16.27) > 0.8
    assert 2.0 < np.mean(carried) < 4.2 and np.mean(np.array(carried) > 16.27) < 0.02


def _sensor_only_truss_nees(seed):
    """The confirmed tracks' centre NEES under their sensor share G after 8 views of a
    five-fruit truss whose every error is the sensors': the camera's calibration biases drawn
    from their prior and a white bearing noise of 0.6 px declared as the sensor's part of a
    noise of 0.4 px (detector, not drawn) and 0.6 px."""
    from bve_mj.estimation.sensor_share import sensor_share

    rng = np.random.default_rng(seed)
    centres, radii = _truss(5, rng)
    bias = rng.normal(0.0, 1.0, 3) * np.array(BIAS_SIGMAS)
    enc = np.diag([(0.6 / F) ** 2] * 2 + [0.0])
    cfg = TrackingConfig(fruits="all", zone_m=0.25, confirm_hits=CONFIRM)
    tracker = Tracker(cfg, centres.mean(axis=0), (0.03, 0.003), UPDATE, _visible(), None, BIAS_SIGMAS)
    for v, (p, R) in enumerate(_views(8)):
        model = BearingSizeModel(p, R, _model(p, R).noise_cov + enc)
        arcs = visible_arc_deg(centres, radii, p, R, F, W, H)
        sightings = [
            Sighting(
                model.predict(np.r_[centres[k], radii[k], bias]) + rng.multivariate_normal(np.zeros(3), enc),
                model,
                enc,
            )
            for k in range(len(centres))
            if arcs[k] >= 150.0
        ]
        tracker.step(sightings, model, v, None)
    out = []
    for t in tracker.confirmed:
        d = t.centre_m - centres[int(np.argmin(np.linalg.norm(centres - t.centre_m, axis=1)))]
        G = sensor_share(t.belief.cov, t.sensor_info)
        assert G is not None and np.linalg.eigvalsh(t.belief.cov - G).min() > -1e-12 * np.trace(G)
        out.append(
            (
                float(d @ np.linalg.solve(G[:3, :3], d)),
                float(np.trace(G[:3, :3]) / np.trace(t.belief.cov[:3, :3])),
            )
        )
    return out


def test_a_tracks_sensor_share_is_the_covariance_of_the_errors_the_sensors_make():
    """Errors made by the sensors alone (calibration biases, white bearing noise declared as
    the sensor's) lie within each track's sensor share G = P·S·P as an honest covariance
    does (mean NEES 3: 3.08 over 60 fruit), G is a real part of P (median 78%), within it;
    with the bearing noise's terms left out of S (the biases' prior alone) the mean is 7.9."""
    rows = [x for seed in range(12) for x in _sensor_only_truss_nees(seed)]
    nees, share = np.array([r[0] for r in rows]), np.array([r[1] for r in rows])
    assert len(rows) >= 40
    assert 2.0 < np.mean(nees) < 4.2 and np.mean(nees > 16.27) < 0.03, np.mean(nees)
    assert 0.2 < np.median(share) < 0.98


def test_a_track_keeps_what_the_detector_saw_of_each_view_it_fused_through_merges():
    """Each sighting's outline (its neighbour share) goes with the view into the track that
    takes it: the first detection's, each fused one's, and a merged track's; a snapshot's list
    is its own."""
    from bve_mj.estimation.noise import Outline

    fruit, r = np.array([0.45, 0.02, 0.3]), 0.027
    cfg = TrackingConfig(fruits="all", zone_m=0.2, gate_probability=1e-6, confirm_hits=2)  # gate shut
    tracker = Tracker(cfg, fruit, (0.03, 0.003), UPDATE, _visible())
    (p0, R0), (p1, R1) = _views(5)[0], _views(5)[4]
    tracker.step([Sighting(_z(fruit, r, p0, R0), _model(p0, R0), outline=Outline(0.2))], _model(p0, R0), 0)
    tracker.step([Sighting(_z(fruit, r, p1, R1), _model(p1, R1), outline=None)], _model(p1, R1), 1)
    (t,) = tracker.tracks  # the two tentative tracks merged
    assert sorted(t.outlines, key=lambda o: -1.0 if o is None else o.neighbour_share) == [None, Outline(0.2)]
    cfg_open = TrackingConfig(fruits="all", zone_m=0.2, confirm_hits=2)
    tracker = Tracker(cfg_open, fruit, (0.03, 0.003), UPDATE, _visible())
    for view, (p, R) in enumerate(_views(3)):
        seen = Sighting(_z(fruit, r, p, R), _model(p, R), outline=Outline(0.1 * view))
        tracker.step([seen], _model(p, R), view)
    (t,) = tracker.tracks
    assert t.hits == 3 and t.outlines == [Outline(0.0), Outline(0.1), Outline(0.2)]
    (copy,) = tracker.snapshot()
    copy.outlines.append(None)
    assert len(t.outlines) == 3
