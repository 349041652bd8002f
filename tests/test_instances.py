"""Touching fruit, fruit in fragments, and what counts as ripe: the detector on rendered
trusses and on synthetic masks.

The truth of every rendered case comes from geometry: a sphere of radius r at range ρ is
the cone of half-angle asin(r/ρ) around the direction to its centre, which images at the
projection of the centre with apparent radius f·tan(asin(r/ρ)).
"""

import math

import cv2
import mujoco
import numpy as np
import pytest

from bve_mj.config import CameraConfig, DetectorConfig, FruitPrior, MeasurementConfig
from bve_mj.errors import ConfigError
from bve_mj.geometry import camera_rotation
from bve_mj.perception import Detection, Intrinsics, NoDetection, Prediction, detect, ripe_mask
from bve_mj.perception.instances import (
    Arc,
    _join_split,
    concave_corners,
    fit_circle,
    group_arcs,
    hull_points,
    outline_arcs,
)
from bve_mj.perception.rims import interior_arcs, interior_edges
from bve_mj.robot import ArmKinematics, get_robot
from bve_mj.sim.render import OffscreenRenderer
from bve_mj.sim.scene import build_scene, set_probe_pose
from bve_mj.sim.scene_model import PROBE_CAMERA, Fruit

CAMERA = CameraConfig()
INTRINSICS = Intrinsics.from_camera(CAMERA)
PRIOR = FruitPrior()
MEAS = MeasurementConfig()
CENTRE_TOL_PX = 1.0
RADIUS_TOL_REL = 0.03
Y = np.array([0.0, 1.0, 0.0])


def _touching(fruit: Fruit, name: str, radius: float, direction) -> Fruit:
    """A red fruit touching ``fruit`` (centre distance r1 + r2) in ``direction``."""
    d = np.asarray(direction, dtype=float)
    return Fruit(name, fruit.centre_m + (fruit.radius_m + radius) * d / np.linalg.norm(d), radius, "red")


def _clusters() -> dict[str, list[Fruit]]:
    """Trusses of touching red spheres, target first, 1.2 m apart along the row."""
    out = {}
    t = Fruit("t_pair", np.array([0.42, 0.0, 0.2]), 0.035, "red")
    out["pair, side by side"] = [t, _touching(t, "n_pair", 0.032, Y)]
    t = Fruit("t_diag", np.array([0.42, 1.2, 0.2]), 0.033, "red")
    out["pair, one below"] = [t, _touching(t, "n_diag", 0.037, [0.0, -0.6, -0.8])]
    t = Fruit("t_line", np.array([0.42, -1.2, 0.2]), 0.034, "red")
    out["triple in a row"] = [t, _touching(t, "n_line1", 0.031, Y), _touching(t, "n_line2", 0.037, -Y)]
    t = Fruit("t_tri", np.array([0.42, 2.4, 0.25]), 0.035, "red")
    below = [
        _touching(t, "n_tri1", 0.034, [0.0, -0.5, -0.866]),
        _touching(t, "n_tri2", 0.036, [0.0, 0.5, -0.866]),
    ]
    out["triple, two below"] = [t, *below]
    return out


# targets partly hidden behind a nearer neighbour: from the robot's side the neighbour's
# centre is 15, 30 and 45 degrees off the line of sight through the target's
HIDDEN = [
    Fruit(f"t_hidden{k}", np.array([0.44, y, 0.2]), 0.033, "red") for k, y in enumerate((-2.4, 3.6, 4.8))
]
HIDERS = [
    _touching(t, f"n_hider{k}", 0.036, [-math.cos(math.radians(a)), math.sin(math.radians(a)), 0.0])
    for k, (t, a) in enumerate(zip(HIDDEN, (15, 30, 45), strict=True))
]
# scene B: a lone sphere, a sphere behind thin green stems, an orange (turning) sphere
LONE = Fruit("t_lone", np.array([0.42, 0.0, 0.2]), 0.035, "red")
STRIPED = Fruit("t_striped", np.array([0.42, 1.2, 0.2]), 0.035, "red")
ORANGE = Fruit("t_orange", np.array([0.42, -1.2, 0.2]), 0.035, "orange")


class Probe:
    """A built scene with the probe camera (the arm is not drawn)."""

    def __init__(self, kin, fruits, edit=None):
        spec, _ = build_scene(
            kin, rng=np.random.default_rng(0), target=fruits[0], distractors=tuple(fruits[1:]), leaves=False
        )
        if edit is not None:
            edit(spec)
        self.model = spec.compile()
        self.data = mujoco.MjData(self.model)
        mujoco.mj_forward(self.model, self.data)
        self.renderer = OffscreenRenderer(
            self.model,
            CAMERA.width_px,
            CAMERA.height_px,
            hidden_groups=(2,),
            blur_sigma_px=CAMERA.blur_sigma_px,
        )

    def view(self, fruit, distance, azimuth_deg, elevation_deg, aim_offset=(0.0, 0.0, 0.0)):
        """The image from ``distance`` off the fruit on the robot's side, turned by the angles;
        and the fruit's true image centre, apparent radius, and the camera pose."""
        a, e = math.radians(azimuth_deg), math.radians(elevation_deg)
        d = np.array([-math.cos(a) * math.cos(e), math.sin(a) * math.cos(e), math.sin(e)])
        p = fruit.centre_m + distance * d
        R = camera_rotation(p, fruit.centre_m + np.asarray(aim_offset))
        set_probe_pose(self.model, self.data, p, R)
        mujoco.mj_forward(self.model, self.data)
        centre, radius = truth(fruit, p, R)
        return self.renderer.render(self.data, PROBE_CAMERA), centre, radius, (p, R)

    def close(self):
        self.renderer.close()


def truth(fruit, p, R):
    """Image centre [px] and apparent radius [px] of a sphere seen from pose (p, R)."""
    pc = R.T @ (fruit.centre_m - p)
    return INTRINSICS.project(pc), CAMERA.focal_px * math.tan(math.asin(fruit.radius_m / np.linalg.norm(pc)))


def verdict(det, centre, radius):
    """'measured' within tolerance, 'refused', or 'wrong' (accepted out of tolerance)."""
    if isinstance(det, NoDetection):
        return "refused"
    ok = (
        np.linalg.norm(det.centre_px - centre) < CENTRE_TOL_PX
        and abs(det.radius_px / radius - 1) < RADIUS_TOL_REL
    )
    return "measured" if ok else "wrong"


def informative(reason: str) -> bool:
    """A refusal says what it saw: a sentence, with the number or the cause."""
    causes = (
        "merged",
        "hidden",
        "visible",
        "outline",
        "arc",
        "speck",
        "implausible",
        "red blob",
        "silhouette",
    )
    return len(reason) >= 20 and any(c in reason for c in causes)


@pytest.fixture(scope="module")
def kin():
    return ArmKinematics(get_robot("manipulator_h"), "emanual")


@pytest.fixture(scope="module")
def trusses(kin):
    clusters = _clusters()
    probe = Probe(kin, [f for fs in clusters.values() for f in fs] + HIDDEN + HIDERS)
    yield probe, clusters
    probe.close()


def _add_stems_across(spec):
    """Three thin green stems 1 cm in front of the striped fruit, across it at 30°."""
    along = np.array([0.0, math.cos(0.5), math.sin(0.5)])
    across = np.array([0.0, -math.sin(0.5), math.cos(0.5)])
    for k in (-1, 0, 1):
        c = STRIPED.centre_m + np.array([-STRIPED.radius_m - 0.01, 0.0, 0.0]) + 0.018 * k * across
        ends = [*(c - 0.06 * along), *(c + 0.06 * along)]
        spec.worldbody.add_geom(
            type=mujoco.mjtGeom.mjGEOM_CAPSULE, size=[0.002, 0, 0], fromto=ends, rgba=[0.30, 0.50, 0.15, 1],
            contype=0, conaffinity=0,
        )  # fmt: skip


@pytest.fixture(scope="module")
def singles(kin):
    probe = Probe(kin, [LONE, STRIPED, ORANGE], edit=_add_stems_across)
    yield probe
    probe.close()


# --------------------------------------------------------------------------- touching fruit
def test_touching_pairs_and_triples_are_measured_within_tolerance_or_refused(trusses):
    """The grid: 4 trusses x 3 distances x 5 azimuths (the neighbours nearer or farther, so
    overlapping in the image by up to ~40% of the radii) x 2 elevations. Never a wrong
    measurement; most measured."""
    probe, clusters = trusses
    counts = {"measured": 0, "refused": 0, "wrong": 0}
    wrong, vague, touched = [], [], []
    for name, fruits in clusters.items():
        target = fruits[0]
        for distance in (0.15, 0.25, 0.4):
            for azimuth in (-40, -20, 0, 20, 40):
                for elevation in (-10, 15):
                    img, centre, radius, (p, R) = probe.view(
                        target, distance, azimuth, elevation, (0.0, 0.004, -0.003)
                    )
                    # the estimate is 5 mm off the truth
                    predicted = INTRINSICS.project(R.T @ (target.centre_m + [0.003, -0.003, 0.003] - p))
                    det = detect(img, INTRINSICS, PRIOR, MEAS, predicted_px=predicted)
                    v = verdict(det, centre, radius)
                    counts[v] += 1
                    case = (name, distance, azimuth, elevation)
                    if v == "wrong":
                        wrong.append((case, np.linalg.norm(det.centre_px - centre), det.radius_px / radius))
                    if isinstance(det, NoDetection) and not informative(det.reason):
                        vague.append((case, det.reason))
                    if v == "measured":
                        touched.append(det.neighbour_share)
    assert not wrong, wrong
    assert not vague, vague
    # a ripe neighbour touches most of these targets' rims somewhere: the noise model's term
    # (measured: every one touched, a fifth of the rim at the median, a third at the 90th %)
    assert np.mean(np.array(touched) > 0.0) > 0.8 and 0.1 < np.median(touched) < 0.5
    total = sum(counts.values())
    assert total == 120
    assert counts["measured"] >= 0.85 * total, counts


def test_rims_over_ripe_neighbours_add_outline_and_measurements_never_wrong_ones(trusses):
    """Rendered trusses, with and without the interior edges (a rim over a ripe neighbour):
    with them the targets show more of their outline and more are measured, and none is
    measured out of tolerance either way."""
    probe, clusters = trusses
    plain = DetectorConfig(interior_edge=0.0)
    assert DetectorConfig().interior_edge > 0.0  # on by default
    measured = {"with": 0, "without": 0}
    arc_gain = []
    for fruits in clusters.values():
        target = fruits[0]
        for distance in (0.15, 0.25):
            for azimuth in (-30, 0, 30):
                img, centre, radius, (p, R) = probe.view(target, distance, azimuth, 15)
                predicted = INTRINSICS.project(R.T @ (target.centre_m + [0.003, -0.003, 0.003] - p))
                dets = {
                    "with": detect(img, INTRINSICS, PRIOR, MEAS, predicted_px=predicted),
                    "without": detect(img, INTRINSICS, PRIOR, MEAS, plain, predicted_px=predicted),
                }
                for k, det in dets.items():
                    v = verdict(det, centre, radius)
                    assert v != "wrong", (k, fruits[0].name, distance, azimuth, det)
                    measured[k] += v == "measured"
                if all(isinstance(d, Detection) for d in dets.values()):
                    arc_gain.append(dets["with"].arc_deg - dets["without"].arc_deg)
    assert measured["with"] >= measured["without"], measured
    assert np.mean(arc_gain) >= 10.0 and min(arc_gain) >= 0.0, arc_gain


def test_a_merged_blob_is_never_one_fruit(trusses):
    """Predicted at the junction of two touching fruit: whichever is measured, it is one of
    them, not the blob of both (whose circle would be about twice as big)."""
    probe, clusters = trusses
    a, b = clusters["pair, side by side"]
    for distance, azimuth in ((0.2, 0), (0.3, 25), (0.3, -25)):
        img, _, _, (p, R) = probe.view(a, distance, azimuth, 5)
        junction = a.centre_m + a.radius_m * (b.centre_m - a.centre_m) / np.linalg.norm(
            b.centre_m - a.centre_m
        )
        det = detect(img, INTRINSICS, PRIOR, MEAS, predicted_px=INTRINSICS.project(R.T @ (junction - p)))
        assert isinstance(det, Detection), det
        assert any(verdict(det, *truth(f, p, R)) == "measured" for f in (a, b))


def test_a_target_partly_hidden_behind_a_nearer_neighbour_is_measured_or_refused(trusses):
    """The nearer neighbour covers a crescent to most of the target: what is left of the
    target's outline is fitted, or the view refused; the neighbour is never taken for it
    (and is measured when it is the one predicted)."""
    probe, _ = trusses
    refused = 0
    for target, hider in zip(HIDDEN, HIDERS, strict=True):
        for distance in (0.2, 0.3, 0.4):
            img, centre, radius, (p, R) = probe.view(target, distance, 0, 0)
            det = detect(img, INTRINSICS, PRIOR, MEAS, predicted_px=centre)
            assert verdict(det, centre, radius) != "wrong", (target.name, distance, det)
            if isinstance(det, NoDetection):
                assert informative(det.reason), det.reason
                refused += 1
            n_centre, n_radius = truth(hider, p, R)
            det = detect(img, INTRINSICS, PRIOR, MEAS, predicted_px=n_centre)
            assert verdict(det, n_centre, n_radius) == "measured", (hider.name, distance, det)
    assert refused >= 1  # the most hidden is too little to measure


def _prediction(p_world, p, R, sigma_m):
    return Prediction(R.T @ (np.asarray(p_world, dtype=float) - p), np.eye(3) * sigma_m**2)


def test_touching_fruit_through_the_closed_loop_path(trusses):
    """The grid again, as the closed loop calls the detector: the estimate 5 mm off with a
    5 mm σ picks its fruit in 3-D, and the fruit is fitted as a spheroid with the world's
    vertical as its axis (these are spheres: the fit must find that too). Never a wrong
    measurement, never ambiguous, most measured."""
    probe, clusters = trusses
    counts = {"measured": 0, "refused": 0, "wrong": 0}
    wrong, ambiguous = [], []
    for name, fruits in clusters.items():
        target = fruits[0]
        for distance in (0.15, 0.25, 0.4):
            for azimuth in (-40, -20, 0, 20, 40):
                img, centre, radius, (p, R) = probe.view(target, distance, azimuth, 15, (0.0, 0.004, -0.003))
                estimate = _prediction(target.centre_m + [0.003, -0.003, 0.003], p, R, 0.005)
                det = detect(img, INTRINSICS, PRIOR, MEAS, prediction=estimate, up_camera=R.T[:, 2])
                v = verdict(det, centre, radius)
                counts[v] += 1
                if v == "wrong":
                    wrong.append(((name, distance, azimuth), np.linalg.norm(det.centre_px - centre)))
                if isinstance(det, NoDetection) and det.ambiguous:
                    ambiguous.append((name, distance, azimuth))
    assert not wrong, wrong
    assert not ambiguous, ambiguous
    assert counts["measured"] >= 0.85 * sum(counts.values()), counts


def test_an_estimate_that_allows_two_touching_fruit_is_ambiguous(trusses):
    """Between two touching fruit with a 3 cm σ, the estimate fits both: no measurement, and
    the reason says so. Narrowed on either fruit, that fruit is measured."""
    probe, clusters = trusses
    a, b = clusters["pair, side by side"]
    img, _, _, (p, R) = probe.view(a, 0.3, 10, 5)
    between = _prediction(0.5 * (a.centre_m + b.centre_m), p, R, 0.03)
    det = detect(img, INTRINSICS, PRIOR, MEAS, prediction=between, up_camera=R.T[:, 2])
    assert isinstance(det, NoDetection) and det.ambiguous and "likelihood ratio" in det.reason, det
    for fruit in (a, b):
        det = detect(img, INTRINSICS, PRIOR, MEAS, prediction=_prediction(fruit.centre_m, p, R, 0.008))
        assert verdict(det, *truth(fruit, p, R)) == "measured", (fruit.name, det)
    # a likelihood ratio the setting accepts as decisive: the likelier one is measured
    loose = DetectorConfig(ambiguity_ratio=1.0001)
    off_a = _prediction(a.centre_m + 0.3 * (b.centre_m - a.centre_m), p, R, 0.03)
    det = detect(img, INTRINSICS, PRIOR, MEAS, loose, prediction=off_a)
    assert verdict(det, *truth(a, p, R)) == "measured", det


# --------------------------------------------------------------------------- one fruit
def test_a_lone_red_sphere_keeps_its_accuracy(singles):
    rng = np.random.default_rng(3)
    for _ in range(6):
        distance = rng.uniform(0.2, 0.6)
        img, centre, radius, (p, _) = singles.view(LONE, distance, rng.uniform(-30, 30), rng.uniform(-15, 25))
        det = detect(img, INTRINSICS, PRIOR, MEAS)
        assert verdict(det, centre, radius) == "measured", det
        assert det.neighbour_share == 0.0  # nothing ripe around it
        # with the true radius the range is exact up to the pixel quantisation of the edge
        rho = np.linalg.norm(LONE.centre_m - p)
        assert det.range_m == pytest.approx(rho, rel=max(0.01, 1.0 / det.radius_px))


def test_a_red_fruit_in_deep_shade_is_seen_and_noisy_dark_grey_is_not(singles):
    """A low sun behind the canopy leaves a ripe fruit dark but red: a drawn scene's fruit had
    values of 22-39 of 255 (RGB about (27, 2, 1)) with the camera's noise. The mask holds such
    a fruit by its chroma and it is measured within tolerance, where a value floor of 40
    loses most of it and refuses it; dark grey with the same noise stays out of the mask (a
    few lone pixels, specks far below a blob) though noise gives its pixels every hue."""
    rng = np.random.default_rng(5)
    img, centre, radius, _ = singles.view(LONE, 0.3, 10, 5)
    dark = np.clip(img * 0.25 + rng.normal(0.0, 3.0, img.shape), 0, 255).astype(np.uint8)
    disc = _discs(img.shape[:2], [((int(centre[0]), int(centre[1])), int(radius) - 2)]) > 0
    assert np.median(cv2.cvtColor(dark, cv2.COLOR_RGB2HSV)[disc][:, 2]) < 32
    assert (ripe_mask(dark, DetectorConfig()) > 0)[disc].mean() > 0.8
    assert verdict(detect(dark, INTRINSICS, PRIOR, MEAS, predicted_px=centre), centre, radius) == "measured"
    floor_40 = DetectorConfig(min_value=40, min_chroma=0)
    assert (ripe_mask(dark, floor_40) > 0)[disc].mean() < 0.5
    assert isinstance(detect(dark, INTRINSICS, PRIOR, MEAS, floor_40, predicted_px=centre), NoDetection)
    grey = np.clip(np.full(img.shape, 20.0) + rng.normal(0.0, 3.0, img.shape), 0, 255).astype(np.uint8)
    hue = cv2.cvtColor(grey, cv2.COLOR_RGB2HSV)[:, :, 0]
    assert ((hue <= 8) | (hue >= 170)).mean() > 0.1  # noise gives grey a red hue
    specks = cv2.connectedComponentsWithStats(ripe_mask(grey, DetectorConfig()))[2][1:, cv2.CC_STAT_AREA]
    assert specks.sum() < 1e-4 * grey[:, :, 0].size and (specks < DetectorConfig().min_area_px).all()


def test_the_expected_size_rejects_an_implausible_fit(singles):
    img, centre, radius, _ = singles.view(LONE, 0.3, 10, 5)
    det = detect(img, INTRINSICS, PRIOR, MEAS, predicted_px=centre, expected_radius_px=radius)
    assert verdict(det, centre, radius) == "measured"
    for wrong_size in (0.4 * radius, 2.5 * radius):
        det = detect(img, INTRINSICS, PRIOR, MEAS, predicted_px=centre, expected_radius_px=wrong_size)
        assert isinstance(det, NoDetection) and "implausible" in det.reason


def test_a_fruit_cut_by_stems_is_fitted_on_all_its_pieces_or_refused(singles):
    """Three green stems across the fruit split its mask into four pieces: their silhouette
    arcs are fitted together (or the view refused)."""
    rng = np.random.default_rng(5)
    counts = {"measured": 0, "refused": 0, "wrong": 0}
    pieces = 0
    for _ in range(12):
        img, centre, radius, _ = singles.view(
            STRIPED, rng.uniform(0.15, 0.45), rng.uniform(-25, 25), rng.uniform(-15, 25)
        )
        n_blobs = cv2.connectedComponents(ripe_mask(img, DetectorConfig()))[0] - 1
        pieces = max(pieces, n_blobs)
        det = detect(img, INTRINSICS, PRIOR, MEAS, predicted_px=centre + rng.uniform(-5, 5, 2))
        counts[verdict(det, centre, radius)] += 1
        if isinstance(det, NoDetection):
            assert informative(det.reason), det.reason
    assert pieces >= 3  # the stems do cut the fruit
    assert counts["wrong"] == 0 and counts["measured"] >= 8, counts


def _blotched(img, centre, radius, rng, n=6):
    """Green blotches painted inside the fruit's disc (uneven colour)."""
    out = img.copy()
    for _ in range(n):
        q = centre + rng.uniform(-0.8, 0.8, 2) * radius
        cv2.circle(out, (int(q[0]), int(q[1])), int(rng.uniform(0.15, 0.3) * radius), (70, 110, 40), -1)
    return out


def _specks(img, centre, radius, rng, n=12):
    """The fruit painted green but for a dozen small red specks (a turning fruit's blush)."""
    out = img.copy()
    yy, xx = np.mgrid[0 : img.shape[0], 0 : img.shape[1]]
    out[(xx + 0.5 - centre[0]) ** 2 + (yy + 0.5 - centre[1]) ** 2 <= (radius + 1.5) ** 2] = (80, 120, 45)
    for _ in range(n):
        q = centre + rng.uniform(-0.7, 0.7, 2) * radius
        cv2.circle(out, (int(q[0]), int(q[1])), max(2, int(0.08 * radius)), (190, 25, 15), -1)
    return out


def test_a_blotched_fruit_is_measured_and_specks_are_never_a_fruit(singles):
    rng = np.random.default_rng(11)
    measured = 0
    for distance in (0.2, 0.3, 0.4):
        for _ in range(2):
            img, centre, radius, _ = singles.view(LONE, distance, rng.uniform(-30, 30), rng.uniform(-10, 25))
            blotched = _blotched(img, centre, radius, rng)
            assert cv2.connectedComponents(ripe_mask(blotched, DetectorConfig()))[0] - 1 >= 1
            v = verdict(detect(blotched, INTRINSICS, PRIOR, MEAS, predicted_px=centre), centre, radius)
            assert v != "wrong"
            measured += v == "measured"
            specks = _specks(img, centre, radius, rng)
            for expected in (None, radius):
                det = detect(
                    specks, INTRINSICS, PRIOR, MEAS, predicted_px=centre, expected_radius_px=expected
                )
                assert isinstance(det, NoDetection) and informative(det.reason), det
    assert measured >= 5


# --------------------------------------------------------------------------- what is ripe
def test_the_ripe_setting_decides_whether_an_orange_fruit_is_seen(singles):
    """By default an orange fruit is not ripe: nothing is seen. When orange counts as ripe
    its coloured skin is segmented and the detector answers about that fruit: measured
    within tolerance or within three of the fit's own σ (which its covariance holds: a blush's
    150° of outline fits to 0.7 px), or refused for what it saw (the scene draws orange as a
    turning fruit, mostly green with an orange blush at the blossom end: too little outline)."""
    ripe_orange = DetectorConfig(ripe_class="orange")
    assert DetectorConfig().ripe_hue_max == DetectorConfig().red_hue_max
    assert ripe_orange.ripe_hue_max > DetectorConfig().ripe_hue_max
    for distance in (0.2, 0.3, 0.4):
        for elevation in (-40, 0, 20):
            img, centre, radius, _ = singles.view(ORANGE, distance, 0, elevation)
            det = detect(img, INTRINSICS, PRIOR, MEAS, predicted_px=centre)
            assert isinstance(det, NoDetection) and "red blob" in det.reason
            disc = np.zeros(img.shape[:2], np.uint8)
            cv2.circle(disc, (int(centre[0]), int(centre[1])), int(radius), 1, -1)
            assert np.count_nonzero(ripe_mask(img, DetectorConfig()) & disc) == 0
            assert np.count_nonzero(ripe_mask(img, ripe_orange) & disc) > 0.03 * disc.sum()
            det = detect(img, INTRINSICS, PRIOR, MEAS, ripe_orange, predicted_px=centre)
            if verdict(det, centre, radius) == "wrong":
                assert np.linalg.norm(det.centre_px - centre) < 3.0 * det.centre_fit_px, det
                radius_tol = RADIUS_TOL_REL + 3.0 * det.radius_fit_px / radius
                assert abs(det.radius_px / radius - 1) < radius_tol, det
            if isinstance(det, NoDetection):
                assert informative(det.reason) and "red blob" not in det.reason, det.reason


def test_orange_skin_joins_the_red_it_touches_but_a_blended_rim_does_not():
    """A red fruit with an orange highlight across its edge: the highlight is its skin and
    the mask is the whole disc; an orange rim a pixel wide (red blended into green leaves)
    does not join; an orange patch apart from any red is not ripe."""
    hsv = np.zeros((200, 300, 3), np.uint8)
    hsv[...] = (60, 160, 90)  # leaves
    cv2.circle(hsv, (100, 100), 50, (175, 220, 180), -1)  # red (hue wraps)
    cv2.circle(hsv, (100, 100), 52, (20, 200, 150), 1)  # the blended rim
    cv2.circle(hsv, (140, 100), 22, (14, 220, 220), -1)  # an orange highlight across its edge
    cv2.circle(hsv, (240, 100), 20, (14, 220, 220), -1)  # an orange fruit, alone
    img = cv2.cvtColor(hsv, cv2.COLOR_HSV2RGB)
    disc = _discs(img.shape[:2], [((100, 100), 50)]) > 0
    highlight = _discs(img.shape[:2], [((140, 100), 22)]) > 0
    mask = ripe_mask(img, DetectorConfig()) > 0
    assert mask[disc & ~highlight].all()
    assert mask[highlight].mean() > 0.98  # all but a pixel-wide tip or two
    rim = (_discs(img.shape[:2], [((100, 100), 54)]) > 0) & ~disc & ~highlight
    assert mask[rim].mean() < 0.01  # a pixel or two where it meets the highlight
    assert not mask[:, 200:].any()
    plain = ripe_mask(img, DetectorConfig(extend_hue_max=0)) > 0
    assert not plain[highlight & ~disc].any()


def test_detector_config_validates_the_new_settings():
    with pytest.raises(ConfigError, match=r"detector\.ripe_class"):
        DetectorConfig(ripe_class="purple")
    with pytest.raises(ConfigError, match=r"detector\.min_arc_deg"):
        DetectorConfig(min_arc_deg=400.0)
    with pytest.raises(ConfigError, match=r"detector\.max_outside_share"):
        DetectorConfig(max_outside_share=1.5)
    limits = DetectorConfig.ripe_hue_limits()
    assert list(limits.values()) == sorted(limits.values())  # riper classes: narrower hue windows
    assert DetectorConfig(ripe_class="red").ripe_hue_max == DetectorConfig().red_hue_max
    for bad in (1.0, 0.5, float("inf"), True):
        with pytest.raises(ConfigError, match=r"detector\.ambiguity_ratio"):
            DetectorConfig(ambiguity_ratio=bad)
    with pytest.raises(ConfigError, match=r"detector\.extend_hue_max"):
        DetectorConfig(extend_hue_max=300)
    for bad in (-1, 256, 17.5, True):
        with pytest.raises(ConfigError, match=r"detector\.min_chroma"):
            DetectorConfig(min_chroma=bad)
    for bad in (-1.0, float("nan"), "80"):
        with pytest.raises(ConfigError, match=r"detector\.interior_edge"):
            DetectorConfig(interior_edge=bad)


# --------------------------------------------------------------------------- synthetic masks
def _outline(mask):
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    return [c[:, 0, :].astype(float) + 0.5 for c in contours]


def _discs(shape, discs):
    mask = np.zeros(shape, np.uint8)
    for (x, y), r in discs:
        cv2.circle(mask, (x, y), r, 255, -1)
    return mask


def test_the_junctions_of_overlapping_discs_are_the_concave_corners():
    (a, ra), (b, rb) = ((100, 100), 50), ((180, 110), 40)
    (outline,) = _outline(_discs((220, 300), [(a, ra), (b, rb)]))
    corners = outline[concave_corners(outline, 1.5)]
    # the circles' intersections, analytically
    a, b = np.array(a, float) + 0.5, np.array(b, float) + 0.5
    d = np.linalg.norm(b - a)
    along = (d * d + ra * ra - rb * rb) / (2 * d)
    mid = a + along * (b - a) / d
    normal = np.array([-(b - a)[1], (b - a)[0]]) / d
    crossings = [mid + s * math.sqrt(ra * ra - along * along) * normal for s in (1, -1)]
    assert len(corners) == 2
    for x in crossings:
        assert min(np.linalg.norm(corners - x, axis=1)) < 2.0
    (single,) = _outline(_discs((220, 300), [((100, 100), 50)]))
    assert len(concave_corners(single, 1.5)) == 0


@pytest.mark.parametrize(
    "discs",
    [
        [((100, 100), 50), ((185, 100), 40)],  # side by side, overlapping
        [((100, 100), 50), ((160, 140), 45)],  # one over the other, much overlap
        [((90, 100), 40), ((165, 100), 38), ((128, 160), 42)],  # three
    ],
)
def test_overlapping_discs_are_separated_into_their_circles(discs):
    mask = _discs((240, 300), discs)
    arcs = []
    for k, outline in enumerate(_outline(mask)):
        arcs += outline_arcs(outline, np.ones(len(outline), bool), k)
    found = group_arcs(arcs)
    assert len(found) == len(discs)
    for (x, y), r in discs:
        best = min(found, key=lambda fr: np.linalg.norm(fr.circle.centre - (x + 0.5, y + 0.5)))
        assert np.linalg.norm(best.circle.centre - (x + 0.5, y + 0.5)) < 1.0
        assert abs(best.circle.radius - r) < 1.0


def test_the_pieces_of_a_disc_cut_by_a_stripe_are_one_fruit():
    mask = _discs((240, 300), [((150, 120), 60)])
    cv2.line(mask, (60, 60), (250, 170), 0, 7)  # a stem across it: two blobs
    outlines = _outline(mask)
    assert len(outlines) == 2
    arcs = []
    for k, outline in enumerate(outlines):
        arcs += outline_arcs(outline, np.ones(len(outline), bool), k)
    found = group_arcs(arcs)
    assert len(found[0].blobs) == 2  # the largest fruit found has arcs of both pieces
    assert np.linalg.norm(found[0].circle.centre - (150.5, 120.5)) < 1.0
    assert abs(found[0].circle.radius - 60) < 1.0


@pytest.mark.parametrize("angle_deg", [0.0, 35.0, 90.0])
def test_the_pieces_of_an_oval_fruit_cut_by_a_stem_are_one_fruit(angle_deg):
    """A fruit that is not a sphere is an ellipse in the image. Cut in two by a stem, the
    circle through each piece's arcs is off by pixels, so each piece lies off the other's
    circle; the circle through both holds them both: one fruit, not two."""
    mask = np.zeros((240, 300), np.uint8)
    cv2.ellipse(mask, (150, 120), (60, 52), angle_deg, 0, 360, 255, -1)
    cv2.line(mask, (60, 40), (240, 200), 0, 9)  # a stem across it, obliquely: two blobs
    outlines = _outline(mask)
    assert len(outlines) == 2
    arcs = []
    for k, outline in enumerate(outlines):
        arcs += outline_arcs(outline, np.ones(len(outline), bool), k)
    found = group_arcs(arcs, shape_rel=0.1)
    assert len(found) == 1 and found[0].blobs == {0, 1}
    assert np.linalg.norm(found[0].circle.centre - (150.5, 120.5)) < 2.0
    assert 52 <= found[0].circle.radius <= 60


@pytest.mark.parametrize(("shown_deg", "joined"), [(240, False), (140, True)])
def test_a_part_that_fixes_its_own_circle_is_not_joined_to_an_arc_off_it(shown_deg, joined):
    """An arc 4-8 px outside a fruit's circle (a fruit behind it, peeping out) lies on the
    circle through both within an oval fruit's allowance. Where the fruit shows 240° of its
    outline its own circle is fixed and the arc is another fruit's: no join. Where it shows
    140°, neither circle is fixed and the two are one fruit's parts: joined."""

    def arc(cx, cy, r, a0, a1):
        t = np.radians(np.arange(a0, a1, 1.0))
        return Arc(np.column_stack((cx + r * np.cos(t), cy + r * np.sin(t))), 0, True)

    half = shown_deg / 2
    a, b = arc(100, 100, 60, 180 - half, 180 + half), arc(104, 100, 64, -50, 50)
    groups = [(fit_circle(a.points), [0]), (fit_circle(b.points), [1])]
    out = _join_split(groups, [a, b], lambda c: max(2.0, 0.04 * c.radius), 0.1)
    assert len(out) == (1 if joined else 2)


def test_hull_points_are_the_convex_silhouette_candidates():
    t = np.linspace(0, 2 * math.pi, 200, endpoint=False)
    rim = np.column_stack((100 + 40 * np.cos(t), 100 + 40 * np.sin(t)))
    inner = np.column_stack((100 + 20 * np.cos(t[::10]), 100 + 20 * np.sin(t[::10])))
    on = hull_points(np.vstack((rim, inner)))
    assert on[: len(rim)].all() and not on[len(rim) :].any()


def _shaded_discs(shape, discs):
    """An RGB image of red discs (later ones in front), each shaded like a lit sphere: bright
    at its centre, darker towards its limb, on a dark green background."""
    img = np.zeros((*shape, 3), np.uint8)
    img[:] = (20, 60, 20)
    v, u = np.mgrid[0 : shape[0], 0 : shape[1]] + 0.5
    for (x, y), r in discs:
        d2 = ((u - x) ** 2 + (v - y) ** 2) / r**2
        inside = d2 <= 1.0
        bright = 90.0 + 150.0 * np.sqrt(np.clip(1.0 - d2, 0.0, 1.0))  # cos of the normal's tilt
        img[inside] = np.stack((bright, 0.08 * bright, 0.08 * bright), axis=-1)[inside].astype(np.uint8)
    return img


def test_a_rim_over_a_ripe_neighbour_is_an_interior_edge_on_its_circle():
    """Red on red: the mask of two overlapping red spheres is one blob, and the front one's
    rim inside it is an edge of brightness (its limb dark against the other's lit face). It
    is found along the front circle (within a pixel of it, over the overlap), and the mask's
    own boundary is not."""
    back, front = ((110, 120), 50), ((185, 125), 45)
    img = _shaded_discs((240, 300), [back, front])
    mask = ripe_mask(img, DetectorConfig())
    (outline,) = _outline(mask)  # one blob
    chains = interior_edges(img, mask, 80.0)
    rims = interior_arcs(chains, [outline - 0.5])  # pieces of 8 pixels or more
    assert rims and all(a.interior and a.blob == 0 for a in rims)
    pts = np.vstack([a.points for a in rims])
    (fx, fy), fr = front
    resid = np.hypot(pts[:, 0] - fx, pts[:, 1] - fy) - fr
    assert np.all(np.abs(resid) < 1.0), resid
    # it spans the overlap: most of the front rim that lies inside the back disc
    (bx, by), br = back
    t = np.linspace(0, 2 * math.pi, 360, endpoint=False)
    rim = np.column_stack((fx + fr * np.cos(t), fy + fr * np.sin(t)))
    covered = np.hypot(rim[:, 0] - bx, rim[:, 1] - by) < br - 4
    near = np.min(
        np.hypot(rim[covered, None, 0] - pts[None, :, 0], rim[covered, None, 1] - pts[None, :, 1]), axis=1
    )
    assert np.mean(near < 2.0) > 0.8
    # the rims join the front fruit's outline arcs, so that fruit shows more of its outline
    plain = outline_arcs(outline, np.ones(len(outline), bool), 0)

    def front_fruit(arcs):
        found = group_arcs(arcs)
        return min(found, key=lambda f: np.linalg.norm(f.circle.centre - (fx, fy)))

    without, with_rims = front_fruit(plain), front_fruit(plain + rims)
    assert any(a.interior for a in with_rims.arcs)
    assert len(with_rims.points) > len(without.points) + 30
    assert np.linalg.norm(with_rims.circle.centre - (fx, fy)) < 1.0
    assert abs(with_rims.circle.radius - fr) < 1.0


def test_an_interior_edge_joins_a_fruit_but_never_makes_one():
    """A ring of edge alone (a highlight's rim, a shadow) is no fruit; the same points as an
    outline arc are."""
    t = np.linspace(0.2, 2.0, 60)
    pts = np.column_stack((100 + 30 * np.cos(t), 100 + 30 * np.sin(t)))
    assert group_arcs([Arc(pts, 0, True, interior=True)]) == []
    assert len(group_arcs([Arc(pts, 0, True)])) == 1
