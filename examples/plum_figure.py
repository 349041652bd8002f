"""A chain of plum tomatoes, its outline arcs grouped as circles and with the fruit's shape undone.

    python examples/plum_figure.py [OUT_DIR]

Renders five touching red plum tomatoes (shape index 1.4, equatorial radius 21 mm) hanging in a
chain, from 0.35 m in front of the middle one, and runs the every-fruit detector twice: with
``detector.shape_grouping = false`` (the arcs grouped by the circles they lie on: one circle
through each end of a plum, each part refused) and with the default (grouped with the fruit
type's mean shape undone: :func:`bve_mj.perception.instances.fruit_stretch`). Writes
OUT_DIR/plum_chain.png (default OUT_DIR: out/, which git ignores). Cyan: each measured fruit,
its fitted centre and equatorial radius; grey: what the detector found and refused; white:
the true silhouettes. Prints each panel's result.
"""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import mujoco
import numpy as np

from bve_mj.cli.script import ScriptParser, folder, guarded
from bve_mj.config import CameraConfig, DetectorConfig, FruitPrior, MeasurementConfig
from bve_mj.geometry import camera_rotation
from bve_mj.perception import Intrinsics
from bve_mj.perception.all_fruit import FruitDetections, detect_all
from bve_mj.robot import ArmKinematics, get_robot
from bve_mj.sim.render import OffscreenRenderer
from bve_mj.sim.scene import build_scene, set_probe_pose
from bve_mj.sim.scene_model import PROBE_CAMERA, Fruit

SHAPE_INDEX, RADIUS_M = 1.4, 0.021


def _chain() -> list[Fruit]:
    """Five plums touching in a chain running sideways and a little down."""
    d = np.array([0.0, 1.0, -0.25]) / math.hypot(1.0, 0.25)
    extent = 1.0 / math.hypot(d[1] / RADIUS_M, d[2] / (SHAPE_INDEX * RADIUS_M))  # along d
    first = np.array([0.42, -0.05, 0.25])
    return [Fruit(f"plum{i}", first + 2 * extent * i * d, RADIUS_M, "red", SHAPE_INDEX) for i in range(5)]


def _silhouette(fruit: Fruit, p: np.ndarray, R: np.ndarray, intr: Intrinsics) -> np.ndarray:
    """The fruit's true outline in the image [px]: the hull of its projected surface."""
    th, ph = np.meshgrid(np.linspace(0.0, math.pi, 91), np.linspace(0.0, 2.0 * math.pi, 181))
    axes = fruit.semi_axes_m
    pts = fruit.centre_m + np.column_stack(
        (axes[0] * (np.sin(th) * np.cos(ph)).ravel(), axes[1] * (np.sin(th) * np.sin(ph)).ravel(),
         axes[2] * np.cos(th).ravel())
    )  # fmt: skip
    uv = np.array([intr.project(R.T @ (q - p)) for q in pts])
    return cv2.convexHull(uv.astype(np.float32)).astype(np.int32)


def _panel(image: np.ndarray, found: FruitDetections, truths: list[np.ndarray], title: str) -> np.ndarray:
    shown = cv2.cvtColor(image, cv2.COLOR_RGB2BGR)
    cv2.polylines(shown, truths, True, (255, 255, 255), 1, cv2.LINE_AA)
    for r in found.refused:
        if r.centre_px is not None and r.radius_px is not None:
            cv2.circle(shown, tuple(round(x) for x in r.centre_px), round(r.radius_px), (150, 150, 150), 1)
    for d in found.detections:
        c = tuple(round(x) for x in d.centre_px)
        cv2.circle(shown, c, round(d.radius_px), (255, 255, 0), 2, cv2.LINE_AA)
        cv2.drawMarker(shown, c, (255, 255, 0), cv2.MARKER_CROSS, 8, 1)
    shown = np.ascontiguousarray(shown[110:390, 140:620])  # the chain
    text = f"{title}: {len(found.detections)} measured, {len(found.refused)} refused"
    cv2.putText(shown, text, (10, 26), cv2.FONT_HERSHEY_SIMPLEX, 0.65, (0, 0, 0), 4, cv2.LINE_AA)
    cv2.putText(shown, text, (10, 26), cv2.FONT_HERSHEY_SIMPLEX, 0.65, (255, 255, 255), 2, cv2.LINE_AA)
    return shown


def main(out_dir: str = "out") -> None:
    camera = CameraConfig()
    intr = Intrinsics.from_camera(camera)
    fruits = _chain()
    kin = ArmKinematics(get_robot("manipulator_h"), "emanual")
    others = (*fruits[:2], *fruits[3:])
    spec, _ = build_scene(
        kin, rng=np.random.default_rng(0), target=fruits[2], distractors=others, leaves=False
    )
    model = spec.compile()
    data = mujoco.MjData(model)
    renderer = OffscreenRenderer(
        model, camera.width_px, camera.height_px, hidden_groups=(2,), blur_sigma_px=camera.blur_sigma_px
    )
    try:
        e = math.radians(10.0)
        p = fruits[2].centre_m + 0.35 * np.array([-math.cos(e), 0.0, math.sin(e)])
        R = camera_rotation(p, fruits[2].centre_m)
        set_probe_pose(model, data, p, R)
        mujoco.mj_forward(model, data)
        image = renderer.render(data, PROBE_CAMERA)
    finally:
        renderer.close()
    prior = FruitPrior(
        radius_m=RADIUS_M, radius_spread_rel=0.1, shape_spread_rel=0.3, shape_index=SHAPE_INDEX
    )
    up = R.T @ np.array([0.0, 0.0, 1.0])
    truths = [_silhouette(f, p, R, intr) for f in fruits]
    panels = []
    for title, cfg in (
        ("as circles", DetectorConfig(shape_grouping=False)),
        ("shape undone", DetectorConfig()),
    ):
        found = detect_all(image, intr, prior, MeasurementConfig(), cfg, up_camera=up)
        centres = [intr.project(R.T @ (f.centre_m - p)) for f in fruits]
        offs = [min(float(np.linalg.norm(d.centre_px - c)) for c in centres) for d in found.detections]
        reasons = "; ".join(sorted({r.reason.split(":")[0] for r in found.refused}))
        centres_px = ", ".join(f"{o:.2f}" for o in offs)
        print(f"{title}: {len(found.detections)} of 5 measured (centres {centres_px} px off the truth), ")
        print(f"  {len(found.refused)} refused: {reasons}")
        panels.append(_panel(image, found, truths, title))
    crop = np.hstack(panels)
    out = Path(out_dir) / "plum_chain.png"
    out.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(out), crop)
    print(f"wrote {out}")


if __name__ == "__main__":
    parser = ScriptParser(description=__doc__.splitlines()[0])
    parser.add_argument("out_dir", nargs="?", type=folder, default="out")
    args = parser.parse_args()
    guarded(lambda: main(args.out_dir))
