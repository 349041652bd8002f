"""Detector accuracy against distance and occlusion, on touching fruit, and render / detect /
build times.

    python benchmarks/bench_perception.py [--views 30] [--skip-leaf]

Accuracy: the probe camera views a fruit of the assumed radius (35 mm) from random
directions on the robot's side, looking within 3 cm of it; a leaf (a thin box on a mocap
body) hides a chosen share of the blob. Range error is the detector's own (with the radius
known); the unknown-radius spread adds ±15% on top, as the covariance states.

Touching fruit: trusses of red spheres that touch (centre distance r1 + r2), a pair side by
side, a pair one below the other, three in a row, one over two; seen from 0.15-0.4 m and
turned so that a neighbour comes nearer or farther and overlaps the target in the image.
Each view is measured within tolerance (centre 1 px, apparent radius 3%), refused, or
wrong (accepted out of tolerance), counted by distance and image overlap
(1 - centre distance / (R1 + R2) with the nearest neighbour, in pixels).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections import Counter, defaultdict

import mujoco
import numpy as np

from bve_mj.cli.script import ScriptParser, guarded, integer
from bve_mj.config import Settings
from bve_mj.geometry import camera_rotation
from bve_mj.perception import Detection, Intrinsics, detect
from bve_mj.robot import ArmKinematics, get_robot
from bve_mj.sim.arm import CAMERA_NAME
from bve_mj.sim.render import OffscreenRenderer, gl_backend
from bve_mj.sim.scene import build_scene, set_probe_pose
from bve_mj.sim.scene_model import PROBE_CAMERA, Fruit


def _leaf_table(kin: ArmKinematics, s: Settings, intr: Intrinsics, target: Fruit, views: int) -> None:
    spec, _ = build_scene(kin, s.scene, np.random.default_rng(0), s.camera, target=target, distractors=())
    leaf_body = spec.worldbody.add_body(name="leaf_body", mocap=True, pos=[0, 5, 0])
    leaf_body.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.002, 0.04, 0.06], rgba=[0.16, 0.42, 0.12, 1])
    model = spec.compile()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    renderer = OffscreenRenderer(
        model, s.camera.width_px, s.camera.height_px, hidden_groups=(2,), blur_sigma_px=s.camera.blur_sigma_px
    )
    leaf = model.body("leaf_body").mocapid[0]
    rng = np.random.default_rng(0)

    print(f"{views} views per cell, fruit radius 35 mm (known), looking within 3 cm of the fruit")
    print(f"{'distance m':>10} {'hidden %':>8} {'range err % (mean |.|, max)':>28} "
          f"{'centre err px (mean, max)':>26} {'detected':>8}")  # fmt: skip
    for distance in (0.2, 0.3, 0.4, 0.5, 0.6):
        for hidden in (0.0, 0.15, 0.30):
            rel, px, found = [], [], 0
            for _ in range(views):
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
                f"{np.mean(px):13.2f} {np.max(px):12.2f} {found:5d}/{views}",
                flush=True,
            )


def _touching(fruit: Fruit, name: str, radius: float, direction: list[float]) -> Fruit:
    d = np.asarray(direction, dtype=float)
    return Fruit(name, fruit.centre_m + (fruit.radius_m + radius) * d / np.linalg.norm(d), radius, "red")


def _trusses() -> dict[str, list[Fruit]]:
    """Touching red spheres, target first, 1.2 m apart along the row (as tests/test_instances.py)."""
    y = [0.0, 1.0, 0.0]
    t1 = Fruit("t_pair", np.array([0.42, 0.0, 0.2]), 0.035, "red")
    t2 = Fruit("t_diag", np.array([0.42, 1.2, 0.2]), 0.033, "red")
    t3 = Fruit("t_line", np.array([0.42, -1.2, 0.2]), 0.034, "red")
    t4 = Fruit("t_tri", np.array([0.42, 2.4, 0.25]), 0.035, "red")
    return {
        "pair, side by side": [t1, _touching(t1, "n_pair", 0.032, y)],
        "pair, one below": [t2, _touching(t2, "n_diag", 0.037, [0.0, -0.6, -0.8])],
        "triple in a row": [
            t3,
            _touching(t3, "n_line1", 0.031, y),
            _touching(t3, "n_line2", 0.037, [0, -1, 0]),
        ],
        "triple, one over two": [
            t4,
            _touching(t4, "n_tri1", 0.034, [0.0, -0.5, -0.866]),
            _touching(t4, "n_tri2", 0.036, [0.0, 0.5, -0.866]),
        ],
    }


def _sphere_image(fruit: Fruit, p: np.ndarray, R: np.ndarray, intr: Intrinsics) -> tuple[np.ndarray, float]:
    pc = R.T @ (fruit.centre_m - p)
    return intr.project(pc), intr.focal_px * math.tan(math.asin(fruit.radius_m / np.linalg.norm(pc)))


def _touching_table(kin: ArmKinematics, s: Settings, intr: Intrinsics) -> None:
    trusses = _trusses()
    fruits = [f for fs in trusses.values() for f in fs]
    spec, _ = build_scene(
        kin,
        s.scene,
        np.random.default_rng(0),
        s.camera,
        target=fruits[0],
        distractors=tuple(fruits[1:]),
        leaves=False,
    )
    model = spec.compile()
    data = mujoco.MjData(model)
    renderer = OffscreenRenderer(
        model, s.camera.width_px, s.camera.height_px, hidden_groups=(2,), blur_sigma_px=s.camera.blur_sigma_px
    )
    counts: dict[tuple[float, str], Counter[str]] = defaultdict(Counter)
    reasons: Counter[str] = Counter()
    t_detect = []
    for fs in trusses.values():
        target = fs[0]
        for distance in (0.15, 0.25, 0.4):
            for azimuth in (-40, -20, 0, 20, 40):
                for elevation in (-10, 15):
                    a, e = math.radians(azimuth), math.radians(elevation)
                    p = target.centre_m + distance * np.array(
                        [-math.cos(a) * math.cos(e), math.sin(a) * math.cos(e), math.sin(e)]
                    )
                    R = camera_rotation(p, target.centre_m + np.array([0.0, 0.004, -0.003]))
                    set_probe_pose(model, data, p, R)
                    mujoco.mj_forward(model, data)
                    img = renderer.render(data, PROBE_CAMERA)
                    centre, radius = _sphere_image(target, p, R, intr)
                    overlap = max(
                        1.0 - float(np.linalg.norm(c - centre)) / (radius + r)
                        for c, r in (_sphere_image(f, p, R, intr) for f in fs[1:])
                    )
                    bucket = next(b for lim, b in _OVERLAPS if overlap < lim)
                    predicted = intr.project(R.T @ (target.centre_m + np.array([0.003, -0.003, 0.003]) - p))
                    t0 = time.perf_counter()
                    det = detect(img, intr, s.fruit, s.measurement, s.detector, predicted)
                    t_detect.append(time.perf_counter() - t0)
                    if isinstance(det, Detection):
                        ok = (
                            np.linalg.norm(det.centre_px - centre) < 1.0
                            and abs(det.radius_px / radius - 1.0) < 0.03
                        )
                        counts[(distance, bucket)]["measured" if ok else "WRONG"] += 1
                    else:
                        counts[(distance, bucket)]["refused"] += 1
                        reasons[det.reason.split(":")[0].split("(")[0].strip()] += 1
    renderer.close()
    print("\ntouching red spheres (4 trusses x 5 azimuths x 2 elevations per distance): "
          "measured within 1 px and 3% / refused / wrong")  # fmt: skip
    print(f"{'distance m':>10} " + " ".join(f"{b:>14}" for _, b in _OVERLAPS))
    for distance in (0.15, 0.25, 0.4):
        cells = []
        for _, b in _OVERLAPS:
            c = counts[(distance, b)]
            cells.append(f"{c['measured']:>4} /{c['refused']:>3} /{c['WRONG']:>2}" if c else f"{'-':>14}")
        print(f"{distance:10.2f} " + " ".join(cells))
    total = Counter[str]()
    for c in counts.values():
        total.update(c)
    print(f"{'all':>10} measured {total['measured']}, refused {total['refused']}, wrong {total['WRONG']}")
    for reason, n in reasons.most_common():
        print(f"{'':>10} refused {n}x: {reason}")
    print(
        f"detect on these views: median {1e3 * np.median(t_detect):.1f} ms, "
        f"max {1e3 * np.max(t_detect):.1f} ms"
    )


_OVERLAPS = (
    (0.05, "touching <5%"),
    (0.15, "overlap 5-15%"),
    (0.3, "overlap 15-30%"),
    (math.inf, "overlap >30%"),
)


def main() -> None:
    ap = ScriptParser()
    ap.add_argument("--views", type=integer(1), default=30)
    ap.add_argument("--skip-leaf", action="store_true", help="skip the (slow) leaf-occlusion table")
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

    print(f"backend {gl_backend()}; scene build + compile {build_ms:.1f} ms (mean of 10 seeds)")
    if not args.skip_leaf:
        _leaf_table(kin, s, intr, target, args.views)
    _touching_table(kin, s, intr)

    # time per frame: render the eye-in-hand camera and detect, shadows off and on (the
    # sun casts them only when the scene says so)
    for shadows in (False, True):
        cfg = dataclasses.replace(s.scene, shadows=shadows)
        spec, info = build_scene(kin, cfg, np.random.default_rng(1), s.camera)
        model = spec.compile()
        data = mujoco.MjData(model)
        mujoco.mj_forward(model, data)
        r = OffscreenRenderer(
            model,
            s.camera.width_px,
            s.camera.height_px,
            shadows=shadows,
            blur_sigma_px=s.camera.blur_sigma_px,
        )
        r.render(data, CAMERA_NAME)
        t_render, t_detect = [], []
        for _ in range(20):
            t0 = time.perf_counter()
            img = r.render(data, CAMERA_NAME)
            t1 = time.perf_counter()
            detect(img, intr, s.fruit, s.measurement)
            t_render.append(t1 - t0)
            t_detect.append(time.perf_counter() - t1)
        # and the probe looking at the target on its truss from 0.3 m (touching fruit in view)
        t_probe, t_truss = [], []
        for k in range(20):
            a = math.radians(-40 + 4 * k)
            p = info.target.centre_m + 0.3 * np.array([-math.cos(a), math.sin(a), 0.1])
            set_probe_pose(model, data, p, camera_rotation(p, info.target.centre_m))
            mujoco.mj_forward(model, data)
            t0 = time.perf_counter()
            img = r.render(data, PROBE_CAMERA)
            t1 = time.perf_counter()
            predicted = intr.project(camera_rotation(p, info.target.centre_m).T @ (info.target.centre_m - p))
            detect(img, intr, s.fruit, s.measurement, s.detector, predicted)
            t_probe.append(t1 - t0)
            t_truss.append(time.perf_counter() - t1)
        r.close()
        print(
            f"640x480 {model.ngeom} geoms, shadows {'on ' if shadows else 'off'}: render "
            f"{1e3 * np.median(t_render):.1f} ms, detect {1e3 * np.median(t_detect):.1f} ms (eye-in-hand at "
            f"home); on the target's truss: render {1e3 * np.median(t_probe):.1f} ms, detect "
            f"{1e3 * np.median(t_truss):.1f} ms (max {1e3 * np.max(t_truss):.1f}) (medians of 20)"
        )


if __name__ == "__main__":
    guarded(main)
