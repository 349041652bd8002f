"""Render the greenhouse: the eye-in-hand view with the detection drawn on it, and an
outside view of the arm before the plant row.

    python examples/render_scene.py [SEED] [OUT_DIR]

Writes OUT_DIR/greenhouse.png (default OUT_DIR: out/, which git ignores): outside view |
eye-in-hand view.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import mujoco
import numpy as np

from bve_mj.cli.script import SEED, ScriptParser, folder, guarded
from bve_mj.config import Settings
from bve_mj.perception import Detection, Intrinsics, detect
from bve_mj.reporting.overlay import draw_detection
from bve_mj.robot import ArmKinematics, get_robot, look_at_ik
from bve_mj.sim.arm import CAMERA_NAME
from bve_mj.sim.render import OffscreenRenderer
from bve_mj.sim.scene import build_scene


def main(seed: int = 4, out_dir: str = "out") -> None:
    s = Settings().for_world("mujoco")  # the closed loop's settings (fruit prior of the scene's type)
    kin = ArmKinematics(get_robot(s.robot.name), s.robot.limit_set)
    spec, info = build_scene(kin, s.scene, np.random.default_rng(seed), s.camera)
    model = spec.compile()
    data = mujoco.MjData(model)
    k = info.target.centre_m
    rng = np.random.default_rng(seed)
    ik = look_at_ik(kin, k + np.array([-0.32, 0.06, 0.08]), k + np.array([0.0, -0.02, 0.03]), kin.home, rng)
    adr = [model.jnt_qposadr[model.joint(n).id] for n in kin.joint_names]
    data.qpos[adr] = ik.q
    mujoco.mj_forward(model, data)
    renderer = OffscreenRenderer(
        model, s.camera.width_px, s.camera.height_px, blur_sigma_px=s.camera.blur_sigma_px
    )
    eye = renderer.render(data, CAMERA_NAME)
    intr = Intrinsics.from_camera(s.camera)
    p, R = kin.camera_pose(ik.q)
    predicted = intr.project(R.T @ (k - p))
    det = detect(eye, intr, s.fruit, s.measurement, s.detector, predicted)
    caption = f"true range {np.linalg.norm(k - p):.3f} m"
    if isinstance(det, Detection):
        caption += f"; assumed r {1e3 * s.fruit.radius_m:.0f} mm, true {1e3 * info.target.radius_m:.1f} mm"
    shown = cv2.cvtColor(draw_detection(eye, det, caption), cv2.COLOR_RGB2BGR)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    outside = cv2.cvtColor(
        renderer.render_free(data, np.array([0.25, 0.0, 0.1]), 1.15, 30, -18), cv2.COLOR_RGB2BGR
    )
    cv2.imwrite(str(out / "greenhouse.png"), np.hstack([outside, shown]))
    print(f"wrote {out / 'greenhouse.png'} (outside view | eye-in-hand view)")
    if isinstance(det, Detection):
        print(
            f"detection: centre ({det.centre_px[0]:.1f}, {det.centre_px[1]:.1f}) px, radius "
            f"{det.radius_px:.1f} px, measured range {det.range_m:.3f} m "
            f"(true {np.linalg.norm(k - p):.3f} m), "
            f"{100 * det.trimmed_fraction:.0f}% of the outline trimmed"
        )
    else:
        print(f"no detection: {det.reason}")


if __name__ == "__main__":
    ap = ScriptParser(description=__doc__.splitlines()[0])
    ap.add_argument("seed", nargs="?", type=SEED, default=4)
    ap.add_argument("out_dir", nargs="?", type=folder, default="out")
    args = ap.parse_args()
    guarded(lambda: main(args.seed, args.out_dir))
