"""Red on red: a truss fruit's rim over a ripe neighbour, with and without interior edges.

    python examples/rims_figure.py [SEED] [OUT_DIR]

Renders the target of the suite's ``truss_cluster`` scene (seeded) from 0.25 m, from the
first of a few directions where the rims change what the detector sees, and writes
OUT_DIR/rims.png (default OUT_DIR: out/, which git ignores): the detector's arcs and fit
without interior edges (left) and with them (right). Cyan: outline arcs of the target's
fruit; yellow: interior edges (rims) that joined it; magenta: the fitted circle; white: the
true silhouette. Prints each panel's result.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import cv2
import mujoco
import numpy as np

from bve_mj.campaigns.scenarios import load_suite
from bve_mj.cli.script import SEED, ScriptParser, folder, guarded
from bve_mj.config import DetectorConfig, Settings
from bve_mj.geometry import camera_rotation
from bve_mj.perception import Detection, Intrinsics, NoDetection, detect, ripe_mask
from bve_mj.perception.instances import group_arcs, outline_arcs
from bve_mj.perception.rims import interior_arcs, interior_edges
from bve_mj.robot import ArmKinematics, get_robot
from bve_mj.sim.render import OffscreenRenderer
from bve_mj.sim.scene import build_scene, set_probe_pose
from bve_mj.sim.scene_model import PROBE_CAMERA


def _panel(
    image: np.ndarray,
    intr: Intrinsics,
    s: Settings,
    cfg: DetectorConfig,
    centre_px: np.ndarray,
    radius_px: float,
    predicted: np.ndarray,
) -> tuple[np.ndarray, Detection | NoDetection]:
    """The image around the target with the arcs of the fruit nearest the truth, the fitted
    circle and the true silhouette; and the detection."""
    det = detect(image, intr, s.fruit, s.measurement, cfg, predicted)
    mask = ripe_mask(image, cfg)
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    outlines = [c[:, 0, :].astype(float) for c in contours]
    arcs = [a for k, o in enumerate(outlines) for a in outline_arcs(o + 0.5, np.ones(len(o), bool), k)]
    if cfg.interior_edge > 0.0:
        arcs += interior_arcs(interior_edges(image, mask, cfg.interior_edge), outlines)
    fruit = group_arcs(arcs, tol_px=cfg.arc_tol_px, shape_rel=s.fruit.shape_spread_rel)
    shown = cv2.cvtColor(image, cv2.COLOR_RGB2BGR)
    if fruit:
        own = min(fruit, key=lambda f: float(np.linalg.norm(f.circle.centre - centre_px)))
        for arc in own.arcs:
            colour = (0, 255, 255) if arc.interior else (255, 255, 0)
            for u, v in arc.points.astype(int):
                cv2.circle(shown, (int(u), int(v)), 1, colour, -1)
    c = (round(float(centre_px[0])), round(float(centre_px[1])))
    cv2.circle(shown, c, round(radius_px), (255, 255, 255), 1)
    if isinstance(det, Detection):
        fit = (round(float(det.centre_px[0])), round(float(det.centre_px[1])))
        cv2.circle(shown, fit, round(det.radius_px), (255, 0, 255), 1)
    half = int(2.2 * radius_px)
    x0, y0 = max(c[0] - half, 0), max(c[1] - half, 0)
    crop = shown[y0 : y0 + 2 * half, x0 : x0 + 2 * half]
    return cv2.resize(crop, (360, 360), interpolation=cv2.INTER_NEAREST), det


def _say(det: Detection | NoDetection, centre_px: np.ndarray, radius_px: float) -> str:
    if not isinstance(det, Detection):
        return f"refused: {det.reason}"
    off = float(np.linalg.norm(det.centre_px - centre_px))
    dr = det.radius_px - radius_px
    return f"centre {off:.2f} px off, radius {dr:+.2f} px, {det.arc_deg:.0f} deg of outline"


def main(seed: int = 4, out_dir: str = "out") -> None:
    (scenario,) = load_suite(only=["truss_cluster"])
    s = scenario.settings()
    kin = ArmKinematics(get_robot(s.robot.name), s.robot.limit_set)
    spec, info = build_scene(kin, s.scene, np.random.default_rng(seed), s.camera)
    model = spec.compile()
    data = mujoco.MjData(model)
    intr = Intrinsics.from_camera(s.camera)
    renderer = OffscreenRenderer(
        model, s.camera.width_px, s.camera.height_px, hidden_groups=(2,), blur_sigma_px=s.camera.blur_sigma_px
    )
    k, r = info.target.centre_m, info.target.radius_m
    plain = dataclasses.replace(s.detector, interior_edge=0.0)
    rims = dataclasses.replace(s.detector, interior_edge=s.detector.interior_edge or 80.0)
    try:
        best = None
        for azimuth in (0, -25, 25, -45, 45, -10, 10):
            a = math.radians(azimuth)
            p = k + 0.25 * np.array([-math.cos(a), math.sin(a), 0.15])
            R = camera_rotation(p, k)
            set_probe_pose(model, data, p, R)
            mujoco.mj_forward(model, data)
            image = renderer.render(data, PROBE_CAMERA)
            t = R.T @ (k - p)
            centre_px = intr.project(t)
            radius_px = s.camera.focal_px * math.tan(math.asin(r / float(np.linalg.norm(t))))
            predicted = intr.project(R.T @ (k + np.array([0.002, -0.002, 0.002]) - p))
            left, d0 = _panel(image, intr, s, plain, centre_px, radius_px, predicted)
            right, d1 = _panel(image, intr, s, rims, centre_px, radius_px, predicted)
            gain = (d1.arc_deg if isinstance(d1, Detection) else 0.0) - (
                d0.arc_deg if isinstance(d0, Detection) else 0.0
            )
            if best is None or gain > best[0]:
                best = (gain, azimuth, left, right, d0, d1, centre_px, radius_px)
            if gain >= 40.0:
                break
    finally:
        renderer.close()
    assert best is not None
    _, azimuth, left, right, d0, d1, centre_px, radius_px = best
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    gap = np.full((360, 8, 3), 255, np.uint8)
    cv2.imwrite(str(out / "rims.png"), np.hstack([left, gap, right]))
    print(f"truss_cluster seed {seed}, target from 0.25 m at azimuth {azimuth} deg")
    print(f"  without interior edges: {_say(d0, centre_px, radius_px)}")
    print(f"  with interior edges:    {_say(d1, centre_px, radius_px)}")
    print(f"wrote {out / 'rims.png'} (without | with)")


if __name__ == "__main__":
    ap = ScriptParser(description=__doc__.splitlines()[0])
    ap.add_argument("seed", nargs="?", type=SEED, default=4)
    ap.add_argument("out_dir", nargs="?", type=folder, default="out")
    args = ap.parse_args()
    guarded(lambda: main(args.seed, args.out_dir))
