"""Elongated and flattened fruit: the silhouette of a spheroid is an ellipse in the image,
and the arcs of a chain of plum tomatoes are grouped with the fruit's shape undone
(:func:`bve_mj.perception.instances.fruit_stretch`), not as circles, which cut each plum in
two (one circle through each end)."""

import math

import cv2
import numpy as np
import pytest

from bve_mj.config import CameraConfig, DetectorConfig, FruitPrior, MeasurementConfig
from bve_mj.errors import ConfigError
from bve_mj.perception import Intrinsics
from bve_mj.perception.all_fruit import detect_all
from bve_mj.perception.instances import fit_circle, fruit_stretch, group_arcs, outline_arcs
from bve_mj.robot import ArmKinematics, get_robot
from bve_mj.sim.scene_model import Fruit

INTRINSICS = Intrinsics.from_camera(CameraConfig())
UP = np.array([0.0, 0.0, 1.0])


def _silhouette_px(centre_camera, radius, shape_index, up):
    """The image outline of a spheroid (axis ``up``): the convex hull of its projected
    surface points [px], (N, 2)."""
    u = up / np.linalg.norm(up)
    a = np.cross(u, [1.0, 0.0, 0.0] if abs(u[0]) < 0.9 else [0.0, 1.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(u, a)
    th, ph = np.meshgrid(np.linspace(0, np.pi, 181), np.linspace(0, 2 * np.pi, 361))
    pts = (
        centre_camera
        + radius * np.sin(th).reshape(-1, 1) * (np.cos(ph).reshape(-1, 1) * a + np.sin(ph).reshape(-1, 1) * b)
        + radius * shape_index * np.cos(th).reshape(-1, 1) * u
    )
    uv = np.array([INTRINSICS.project(p) for p in pts])
    return cv2.convexHull(uv.astype(np.float32)).reshape(-1, 2).astype(float)


def _roundness(points):
    """rms of the points' distances from their fitted circle over its radius."""
    c = fit_circle(points)
    d = np.hypot(*(points - c.centre).T)
    return float(np.sqrt(np.mean((d - c.radius) ** 2)) / c.radius)


@pytest.mark.parametrize("shape_index", [1.4, 0.75])
@pytest.mark.parametrize(
    ("elevation_deg", "offset_m"), [(0.0, (0.0, 0.0)), (35.0, (0.06, 0.04)), (-25.0, (-0.05, 0.0))]
)
def test_the_stretch_makes_a_spheroids_silhouette_a_circle(shape_index, elevation_deg, offset_m):
    """A plum (1.4) and a flattened beefsteak (0.75) hanging plumb, seen from above, level
    or below and off the image centre: their outline is an ellipse (rms off its circle
    several % of the radius), and under the map as round as a sphere's there (perspective
    makes that an ellipse off the image centre: the map undoes the shape, not the
    perspective), at the image centre a circle of the equatorial radius."""
    e = math.radians(elevation_deg)
    up = np.array([math.sin(e), 0.0, math.cos(e)])  # the camera pitched by e
    centre = np.array([0.25, *offset_m])
    outline = _silhouette_px(centre, 0.025, shape_index, up)
    M = fruit_stretch(INTRINSICS, up, shape_index, outline.mean(axis=0))
    assert M is not None
    sphere = _silhouette_px(centre, 0.025, 1.0, up)  # off the image centre, itself an ellipse
    assert _roundness(outline) > _roundness(sphere) + 0.02
    assert _roundness(outline @ M.T) < _roundness(sphere) + 0.003
    if offset_m == (0.0, 0.0):  # off the image centre perspective widens the outline a little
        equatorial = INTRINSICS.focal_px * math.tan(math.asin(0.025 / np.linalg.norm(centre)))
        assert fit_circle(outline @ M.T).radius == pytest.approx(equatorial, rel=0.01)


def test_the_stretch_is_none_where_it_cannot_be_known_and_round_fruit_are_left_alone():
    at = np.array([320.0, 240.0])
    assert fruit_stretch(INTRINSICS, None, 1.4, at) is None
    assert fruit_stretch(INTRINSICS, np.array([0.0, 0.0, 0.0]), 1.4, at) is None
    assert fruit_stretch(INTRINSICS, np.array([1.0, 0.0, 0.0]), 1.4, at) is None  # seen end-on
    assert np.allclose(fruit_stretch(INTRINSICS, UP, 1.0, at), np.eye(2))
    M = fruit_stretch(INTRINSICS, UP, 1.4, at)  # level, the vertical is the image's v axis
    assert np.allclose(M, np.diag([1.0, 1.0 / 1.4]), atol=1e-6)


def _outlines(mask):
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    return [c[:, 0, :].astype(float) + 0.5 for c in contours]


@pytest.mark.parametrize(
    "centres",
    [
        [(80, 80), (125, 125), (170, 170), (215, 215)],  # a chain hanging down to the side
        [(90, 100), (150, 110), (210, 100)],  # side by side
    ],
)
def test_a_chain_of_overlapping_ellipses_is_one_fruit_each(centres):
    """Touching plums (semi-axes 30 and 42 px, upright) overlap into one blob. Grouped as
    circles, each inner plum is cut in two; with the shape undone, one fruit each, its
    centre and equatorial radius exact."""
    mask = np.zeros((300, 320), np.uint8)
    for c in centres:
        cv2.ellipse(mask, c, (30, 42), 0, 0, 360, 255, -1)
    arcs = []
    for k, outline in enumerate(_outlines(mask)):
        arcs += outline_arcs(outline, np.ones(len(outline), bool), k)
    M = np.diag([1.0, 30.0 / 42.0])
    found = group_arcs(arcs, shape_rel=0.3, stretch=M)
    assert len(found) == len(centres)
    for x, y in centres:
        best = min(found, key=lambda fr: np.linalg.norm(fr.circle.centre - (x + 0.5, y + 0.5)))
        assert np.linalg.norm(best.circle.centre - (x + 0.5, y + 0.5)) < 1.0
        assert abs(best.circle.radius - 30.0) < 1.0
    assert len(group_arcs(arcs, shape_rel=0.3)) > len(centres)  # circles cut them


@pytest.fixture(scope="module")
def plum_chain():
    from tests.test_instances import Probe

    k, r = 1.4, 0.021
    d = np.array([0.0, 1.0, -0.25])  # nearly side by side, a little lower each
    d /= np.linalg.norm(d)
    extent = 1.0 / math.sqrt((d[0] ** 2 + d[1] ** 2) / r**2 + d[2] ** 2 / (k * r) ** 2)
    fruits = [
        Fruit(f"plum{i}", np.array([0.42, -0.05, 0.25]) + 2 * extent * i * d, r, "red", k) for i in range(5)
    ]
    probe = Probe(ArmKinematics(get_robot("manipulator_h"), "emanual"), fruits)
    yield probe, fruits, FruitPrior(radius_m=r, radius_spread_rel=0.1, shape_spread_rel=0.3, shape_index=k)
    probe.close()


def _count(probe, fruits, prior, config=None):
    counts = {"measured": 0, "wrong": 0}
    for azimuth in (-30, 0, 30):
        for elevation in (-15, 10, 30):
            img, _, _, (p, R) = probe.view(fruits[2], 0.35, azimuth, elevation)
            found = detect_all(img, INTRINSICS, prior, MeasurementConfig(), config, up_camera=R.T @ UP)
            truths = [INTRINSICS.project(R.T @ (f.centre_m - p)) for f in fruits]
            for det in found.detections:
                off = min(np.linalg.norm(det.centre_px - t) for t in truths)
                counts["wrong" if off > 2.0 else "measured"] += 1
    return counts


def test_a_rendered_chain_of_plums_is_measured_fruit_by_fruit(plum_chain):
    """Five touching plum tomatoes (shape index 1.4) in a chain, from nine directions at
    0.35 m: with the shape undone most fruit-views are measured (34 of 45 when written), as
    circles few (11: each plum cut in two, its parts refused as partial), and no more of
    them off by over 2 px (1 and 2 when written: views from above, where the plums overlap
    most)."""
    probe, fruits, prior = plum_chain
    shaped = _count(probe, fruits, prior)
    circles = _count(probe, fruits, prior, DetectorConfig(shape_grouping=False))
    assert shaped["measured"] >= 0.6 * 5 * 9
    assert shaped["measured"] >= 2 * circles["measured"]
    assert shaped["wrong"] <= max(circles["wrong"], 2)


def test_shape_grouping_is_validated():
    for bad in ("yes", 1, None):
        with pytest.raises(ConfigError, match=r"detector\.shape_grouping"):
            DetectorConfig(shape_grouping=bad)
