"""Detector accuracy against distance and occlusion, and render / detect / build times.

    python benchmarks/bench_perception.py [--views 30]

Accuracy: the probe camera views a fruit of the assumed radius (35 mm) from random
directions on the robot's side, looking within 3 cm of it; a leaf (a thin box on a mocap
body) hides a chosen share of the blob. Range error is the detector's own (with the radius
known); the unknown-radius spread adds ±15% on top, as the covariance states.
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import mujoco
import numpy as np

from bve_mj.config import Settings
from bve_mj.geometry import camera_rotation
from bve_mj.perception import Detection, Intrinsics, detect
from bve_mj.robot import ArmKinematics, get_robot
from bve_mj.sim.arm import CAMERA_NAME
from bve_mj.sim.render import OffscreenRenderer, gl_backend
from bve_mj.sim.scene import PROBE_CAMERA, Fruit, build_scene, set_probe_pose


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--views", type=int, default=30)
    args = ap.parse_args()
    s = Settings()
    kin = ArmKinematics(get_robot("manipulator_h"), "emanual")
    intr = Intrinsics.from_camera(s.camera)
    target = Fruit("target", np.array([0.42, 0.0, 0.2]), s.fruit.radius_m, "red")

    t0 = time.perf_counter()
    for seed in range(10):
        spec, _ = build_scene(kin, s.scene, np.random.default_rng(seed), s.camera)
        spec.compile()
    build_ms = (time.perf_counter() - t0) / 10 * 1e3

    spec, _ = build_scene(kin, s.scene, np.random.default_rng(0), s.camera, target=target, distractors=())
    leaf_body = spec.worldbody.add_body(name="leaf_body", mocap=True, pos=[0, 5, 0])
    leaf_body.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.002, 0.04, 0.06], rgba=[0.16, 0.42, 0.12, 1])
    model = spec.compile()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    renderer = OffscreenRenderer(model, s.camera.width_px, s.camera.height_px, hidden_groups=(2,))
    leaf = model.body("leaf_body").mocapid[0]
    rng = np.random.default_rng(0)

    print(f"backend {gl_backend()}; scene build + compile {build_ms:.1f} ms (mean of 10 seeds)")
    print(f"{args.views} views per cell, fruit radius 35 mm (known), looking within 3 cm of the fruit")
    print(f"{'distance m':>10} {'hidden %':>8} {'range err % (mean |.|, max)':>28} "
          f"{'centre err px (mean, max)':>26} {'detected':>8}")  # fmt: skip
    for distance in (0.2, 0.3, 0.4, 0.5, 0.6):
        for hidden in (0.0, 0.15, 0.30):
            rel, px, found = [], [], 0
            for _ in range(args.views):
                d = np.array([-1.0, rng.uniform(-0.5, 0.5), rng.uniform(-0.3, 0.5)])
                p_cam = target.centre_m + distance * d / np.linalg.norm(d)
                aim = target.centre_m + rng.uniform(-0.03, 0.03, 3)
                R = camera_rotation(p_cam, aim)
                set_probe_pose(model, data, p_cam, R)
                data.mocap_pos[leaf] = [0, 5, 0]
                mujoco.mj_forward(model, data)
                clear = detect(renderer.render(data, PROBE_CAMERA), intr, s.fruit, s.measurement)
                if hidden > 0 and isinstance(clear, Detection):
                    # slide a leaf (in a plane 4 cm before the fruit) in from the side until
                    # the blob has lost the requested share
                    side = R[:, 1] if rng.random() < 0.5 else -R[:, 1]
                    for shift in np.linspace(0.12, 0.0, 121):
                        data.mocap_pos[leaf] = target.centre_m - 0.04 * R[:, 0] + shift * side
                        rot = np.zeros(4)
                        mujoco.mju_mat2Quat(rot, R.reshape(9))
                        data.mocap_quat[leaf] = rot
                        mujoco.mj_forward(model, data)
                        img = renderer.render(data, PROBE_CAMERA)
                        det = detect(img, intr, s.fruit, s.measurement)
                        if not isinstance(det, Detection) or det.area_px <= (1 - hidden) * clear.area_px:
                            break
                else:
                    det = clear
                truth = R.T @ (target.centre_m - p_cam)
                if isinstance(det, Detection):
                    found += 1
                    rel.append(100 * abs(det.range_m - np.linalg.norm(truth)) / np.linalg.norm(truth))
                    px.append(float(np.linalg.norm(det.centre_px - intr.project(truth))))
            print(
                f"{distance:10.1f} {100 * hidden:8.0f} {np.mean(rel):14.2f} {np.max(rel):13.2f} "
                f"{np.mean(px):13.2f} {np.max(px):12.2f} {found:5d}/{args.views}",
                flush=True,
            )

    # time per frame: render the eye-in-hand camera and detect, shadows off and on (the
    # sun casts them only when the scene says so)
    for shadows in (False, True):
        cfg = dataclasses.replace(s.scene, shadows=shadows)
        spec, _ = build_scene(kin, cfg, np.random.default_rng(1), s.camera)
        model = spec.compile()
        data = mujoco.MjData(model)
        mujoco.mj_forward(model, data)
        r = OffscreenRenderer(model, s.camera.width_px, s.camera.height_px, shadows=shadows)
        r.render(data, CAMERA_NAME)
        t_render, t_detect = [], []
        for _ in range(20):
            t0 = time.perf_counter()
            img = r.render(data, CAMERA_NAME)
            t1 = time.perf_counter()
            detect(img, intr, s.fruit, s.measurement)
            t_render.append(t1 - t0)
            t_detect.append(time.perf_counter() - t1)
        r.close()
        print(
            f"640x480 {model.ngeom} geoms, shadows {'on ' if shadows else 'off'}: render "
            f"{1e3 * np.median(t_render):.1f} ms, detect {1e3 * np.median(t_detect):.1f} ms (median of 20)"
        )


if __name__ == "__main__":
    main()
