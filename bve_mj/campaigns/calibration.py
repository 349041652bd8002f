"""Noise calibration: the detector against ground truth, over the scenes it will meet.

For each scenario of the suite (or any scenario files) and each of ``scenes`` seeded scenes
of it, the arm takes ``views`` look-at poses around the target (the pose sampler below),
the eye-in-hand image is rendered and the detector measures, given a prediction of the
target as the closed loop gives it (its mean a few millimetres off the truth, its
covariance saying so). Every detection is compared with the truth: the error of the
bearing of the centre (the two normalised image coordinates) and of the apparent
(equatorial) angular radius, in pixels (f · angle), beside what the detector saw (apparent
radius, share of the outline, trimmed share, the fit's own σ and the arcs' jackknife
spread). :func:`bve_mj.estimation.noise_fit.fit_noise_model` turns the samples into the
noise model the filter uses.

Sensor realism is off here (no image noise unless the scenario asks for it, no calibration
error, exact encoders): the camera's calibration error and the encoders' noise are declared
apart (``sensor``), as biases in the state and white noise in R.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from bve_mj.campaigns.scenarios import Scenario
from bve_mj.errors import ConfigError
from bve_mj.estimation.noise import NoiseModel
from bve_mj.estimation.noise_fit import fit_noise_model

__all__ = ["CalibrationData", "calibrate", "run_calibration", "sample_views"]

_DISTANCE_M = (0.12, 0.45)  # camera to fruit centre
_AZIMUTH_DEG = 70.0  # either side of the robot's side of the fruit (-x)
_ELEVATION_DEG = (-35.0, 55.0)
_AIM_SIGMA_M = (0.0005, 0.008)  # the loop's estimate error when it looks (its σ drawn here)
_ATTEMPTS = 8  # candidate poses tried per view asked for (the arm reaches about a third)


def sample_views(name: str, settings: Any, scene_seed: int, views: int) -> list[dict[str, Any]]:
    """Render ``views`` look-at views of the target of one seeded scene of ``settings``
    (closed-loop settings of a scenario) and detect it in each: one row per view that
    the arm could take, with the detector's answer and the truth."""
    import mujoco

    from bve_mj.perception.detection import Detection, Intrinsics, Prediction
    from bve_mj.perception.detector import detect
    from bve_mj.robot import IkOptions, arm_kinematics, look_at_ik
    from bve_mj.sim.arm import CAMERA_NAME
    from bve_mj.sim.mujoco_world import declared_noise
    from bve_mj.sim.render import OffscreenRenderer
    from bve_mj.sim.scene import build_scene
    from bve_mj.sim.sensors import noisy_image

    scene_ss, view_ss = np.random.SeedSequence(scene_seed).spawn(2)
    rng = np.random.default_rng(view_ss)
    kin = arm_kinematics(settings.robot.name, settings.robot.limit_set)
    spec, info = build_scene(kin, settings.scene, np.random.default_rng(scene_ss), settings.camera)
    model = spec.compile()
    data = mujoco.MjData(model)
    adr = np.array([model.jnt_qposadr[model.joint(n).id] for n in kin.joint_names])
    cam = settings.camera
    f = cam.focal_px
    intrinsics = Intrinsics.from_camera(cam)
    measurement, fruit = declared_noise(settings)
    target = info.target
    truth = target.centre_m
    rows: list[dict[str, Any]] = []
    renderer = OffscreenRenderer(
        model, cam.width_px, cam.height_px, shadows=settings.scene.shadows, blur_sigma_px=cam.blur_sigma_px
    )
    q_seed = kin.home.copy()
    try:
        view, attempts = 0, 0
        while view < views and attempts < _ATTEMPTS * views:  # about a third are reachable
            attempts += 1
            az = math.radians(rng.uniform(-_AZIMUTH_DEG, _AZIMUTH_DEG))
            el = math.radians(rng.uniform(*_ELEVATION_DEG))
            rho = rng.uniform(*_DISTANCE_M)
            direction = np.array([-math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
            sigma_aim = math.exp(rng.uniform(*np.log(_AIM_SIGMA_M)))
            aim = truth + rng.normal(0.0, sigma_aim, 3)
            ik = look_at_ik(kin, truth + rho * direction, aim, q_seed, rng, IkOptions(restarts=2))
            if not ik.success:
                continue
            view += 1
            q_seed = ik.q
            data.qpos[adr] = ik.q
            mujoco.mj_forward(model, data)
            image = noisy_image(renderer.render(data, CAMERA_NAME), settings.sensor, rng)
            p, R = kin.camera_pose(ik.q)
            t = R.T @ (truth - p)
            prediction = Prediction(R.T @ (aim - p), np.eye(3) * sigma_aim**2)
            det = detect(
                image, intrinsics, fruit, measurement, settings.detector,
                prediction=prediction, up_camera=R.T[:, 2],
            )  # fmt: skip
            row: dict[str, Any] = {
                "scenario": name,
                "scene_seed": scene_seed,
                "view": view,
                "distance_m": float(np.linalg.norm(t)),
                "off_axis_px": float(f * math.hypot(t[1], t[2]) / t[0]),
                "aim_sigma_m": sigma_aim,
                "true_radius_m": target.radius_m,
                "shape_index": target.shape_index,
                "colour": target.colour,
                "fruit_shape_index": fruit.shape_index,
                "camera_position_m": p.tolist(),
                "camera_rotation": R.tolist(),
                "truth_m": truth.tolist(),
            }
            if isinstance(det, Detection):
                a = det.bearing_camera
                alpha_true = math.asin(min(target.radius_m / float(np.linalg.norm(t)), 1.0))
                row.update(
                    detected=True,
                    radius_px=det.radius_px,
                    arc_deg=det.arc_deg,
                    trimmed_fraction=det.trimmed_fraction,
                    centre_fit_px=det.centre_fit_px,
                    radius_fit_px=det.radius_fit_px,
                    centre_jackknife_px=det.centre_jackknife_px,
                    radius_jackknife_px=det.radius_jackknife_px,
                    neighbour_share=det.neighbour_share,
                    centre_disagreement_px=det.centre_disagreement_px,
                    err_u_px=float(f * (a[1] / a[0] - t[1] / t[0])),
                    err_v_px=float(f * (a[2] / a[0] - t[2] / t[0])),
                    err_alpha_px=float(f * (det.angular_radius_rad - alpha_true)),
                )

            else:
                row.update(detected=False, reason=det.reason)
            rows.append(row)
    finally:
        renderer.close()
    return rows


Task = tuple[str, Any, int, int]


def _run_task(task: Task) -> list[dict[str, Any]]:
    from bve_mj.threads import one_blas_thread

    name, settings, scene_seed, views = task
    with one_blas_thread():
        return sample_views(name, settings, scene_seed, views)


@dataclass(frozen=True)
class CalibrationData:
    """Every rendered view's row, the scenarios and seeds they came from, and the wall time."""

    rows: tuple[dict[str, Any], ...]
    scenarios: tuple[str, ...]
    scenes: int
    views: int
    seed: int
    wall_s: float

    @property
    def detections(self) -> list[dict[str, Any]]:
        return [r for r in self.rows if r.get("detected")]


def run_calibration(
    scenarios: Sequence[Scenario],
    *,
    scenes: int = 8,
    views: int = 25,
    seed: int = 1,
    workers: int | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> CalibrationData:
    """``views`` views of ``scenes`` seeded scenes of every scenario, in spawned workers."""
    from bve_mj.campaigns.executors import local_batches
    from bve_mj.campaigns.spec import episode_seed

    for field, value, lo in (("scenes", scenes, 1), ("views", views, 1), ("seed", seed, 0)):
        if isinstance(value, bool) or not isinstance(value, int) or value < lo:
            raise ConfigError(field, value, f"an integer >= {lo}")
    workers = (os.cpu_count() or 1) if workers is None else workers
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ConfigError("workers", workers, "an integer >= 1")
    t0 = time.perf_counter()
    tasks: list[Task] = [
        (sc.name, sc.settings("camera"), episode_seed(seed, k), views)
        for sc in scenarios
        for k in range(scenes)
    ]
    rows: list[dict[str, Any]] = []
    if progress is not None:
        progress(0, len(tasks))
    for done, batch in enumerate(local_batches(_run_task, tasks, min(workers, len(tasks))), start=1):
        rows.extend(batch)
        if progress is not None:
            progress(done, len(tasks))
    rows.sort(key=lambda r: (r["scenario"], r["scene_seed"], r["view"]))
    return CalibrationData(
        tuple(rows), tuple(sc.name for sc in scenarios), scenes, views, seed, time.perf_counter() - t0
    )


def calibrate(
    scenarios: Sequence[Scenario],
    *,
    scenes: int = 8,
    views: int = 25,
    seed: int = 1,
    workers: int | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> tuple[NoiseModel, dict[str, Any], CalibrationData]:
    """Render and detect (:func:`run_calibration`), then fit the noise model
    (:func:`~bve_mj.estimation.noise_fit.fit_noise_model`): the model, how well it describes the
    samples, and the samples. The default seed (1) keeps the scenario suite's episodes
    (seeds 0 and 7777 there) out of the calibration."""
    data = run_calibration(
        scenarios, scenes=scenes, views=views, seed=seed, workers=workers, progress=progress
    )
    camera = scenarios[0].settings("camera").camera
    for sc in scenarios[1:]:
        if sc.settings("camera").camera != camera:
            raise ConfigError(
                "scenarios", sc.name, "scenarios that share one camera (the model is per camera)"
            )
    names = ",".join(data.scenarios)
    source = f"bve-mj calibrate: scenarios {names}; {scenes} scenes x {views} views each, seed {seed}"
    model, report = fit_noise_model(data.rows, camera, source)  # the refusals fit the refusal scale
    report["views"] = len(data.rows)
    report["refused"] = len(data.rows) - len(data.detections)
    return model, report, data
