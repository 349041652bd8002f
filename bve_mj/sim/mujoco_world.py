"""The rendered world: plan → IK → drive → render → detect → measurement.

The filter is given the camera pose the arm actually reached, as its joint encoders report
it, through forward kinematics; never the planned pose.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import mujoco
import numpy as np

from bve_mj.config import FruitPrior, MeasurementConfig, Settings
from bve_mj.estimation.assignment import Sighting, detected_outline
from bve_mj.estimation.belief import Belief
from bve_mj.estimation.measure import measure
from bve_mj.estimation.models import BearingSizeModel, CameraModel, RangeModel, SizeModel
from bve_mj.estimation.noise import NoiseModel
from bve_mj.estimation.partial_colour import detector_noise_model
from bve_mj.estimation.unmeasured import unmeasured_sighting
from bve_mj.perception.detection import Detection, NoDetection, Prediction
from bve_mj.perception.protocol import DetectionRequest, Detector, EveryFruitDetector, detector_from_settings
from bve_mj.planning.plan import ViewPlan
from bve_mj.robot.ik import IkOptions, look_at_ik
from bve_mj.robot.kinematics import ArmKinematics
from bve_mj.sim.arm import CAMERA_NAME
from bve_mj.sim.basket import Basket
from bve_mj.sim.controller import JointTrajectoryController, MoveReport
from bve_mj.sim.render import OffscreenRenderer
from bve_mj.sim.scene_model import SceneInfo
from bve_mj.sim.sensors import calibrated_intrinsics, noisy_encoders, noisy_image
from bve_mj.sim.true_boxes import true_boxes
from bve_mj.sim.world import Observation

__all__ = ["MujocoWorld", "ViewTimings", "declared_noise"]


def declared_noise(settings: Settings) -> tuple[MeasurementConfig, FruitPrior]:
    """The measurement noise the filter is told, with the sensor model's errors folded in.

    A principal-point error and encoder noise (through the focal length) move the blob
    centre: they add in quadrature to its pixel σ. A focal-length error scales the range:
    it adds to the relative range σ (as an equivalent uniform radius spread).
    """
    s, cam = settings.sensor, settings.camera
    centre = math.sqrt(
        settings.measurement.centre_sigma_px**2
        + s.principal_point_error_px**2
        + (2.5 * s.encoder_noise_rad * cam.focal_px) ** 2  # ~6 joints' errors at the camera
    )
    spread = math.sqrt(settings.fruit.radius_spread_rel**2 + 3.0 * s.focal_error_rel**2)
    return (
        dataclasses.replace(settings.measurement, centre_sigma_px=centre),
        dataclasses.replace(settings.fruit, radius_spread_rel=min(spread, 0.99)),
    )


@dataclass
class ViewTimings:
    """Wall time of one view's stages [s] (planning is timed by the episode loop).

    ``ik_s``: look-at IK in the move (zero when the plan carries its joint angles, as the
    joint-space BVE's do: its IK is part of planning); ``control_s``: physics of the move;
    ``record_s``: the ``on_step`` hook during the move (a video's frames), kept out of
    ``control_s``."""

    ik_s: float = 0.0
    control_s: float = 0.0
    record_s: float = 0.0
    render_s: float = 0.0
    detect_s: float = 0.0


@dataclass
class _Last:
    move: MoveReport | None = None
    ik_failed: bool = False
    detection: Detection | NoDetection | None = None
    q: np.ndarray | None = None
    q_encoders: np.ndarray | None = None
    image: np.ndarray | None = None
    measurement: tuple[np.ndarray, np.ndarray] | None = None  # z and its covariance as fused
    every: Any = None  # every fruit's detections (FruitDetections), in the every-fruit loop
    timings: ViewTimings = field(default_factory=ViewTimings)


class MujocoWorld:
    """The arm in the greenhouse scene, seen through its eye-in-hand camera.

    Args:
        settings: every setting (camera, sensor, detector, measurement, fruit prior).
        kin: the arm's kinematics (the same URDF the scene's arm was compiled from).
        model: the compiled scene; info: its ground truth.
        q_start: the joint configuration the arm starts in.
        target: the point the camera looks at first (the prior's mean).
        rng: seeds the sensor noise and the calibration error.
        keep_images: keep the last eye-in-hand image (for videos).
        on_step: called with the simulation time after every physics step of a move.
        noise: the detector's calibrated noise when the radius is in the state (default:
            loaded from ``measurement.noise_model``).
        detector: what measures the fruit in each image (the
            :class:`~bve_mj.perception.protocol.Detector` protocol; default: the one
            ``detector.kind`` names, :func:`~bve_mj.perception.protocol.detector_from_settings`:
            the built-in colour detector, or synthetic boxes from the scene's ground truth).
    """

    def __init__(
        self,
        settings: Settings,
        kin: ArmKinematics,
        model: mujoco.MjModel,
        info: SceneInfo,
        q_start: np.ndarray,
        target: np.ndarray,
        rng: np.random.Generator,
        *,
        keep_images: bool = False,
        on_step: Callable[[float], None] | None = None,
        noise: NoiseModel | None = None,
        detector: Detector | None = None,
    ) -> None:
        self.settings, self.kin, self.model, self.info = settings, kin, model, info
        self.data = mujoco.MjData(model)
        joints = [model.joint(n).id for n in kin.joint_names]
        self.qpos_adr = np.array([model.jnt_qposadr[j] for j in joints])
        dof_adr = np.array([model.jnt_dofadr[j] for j in joints])
        by_joint = {int(model.actuator_trnid[a, 0]): a for a in range(model.nu)}
        ctrl_ids = np.array([by_joint[j] for j in joints])
        self.controller = JointTrajectoryController(self.model, self.data, self.qpos_adr, dof_adr, ctrl_ids)
        self.data.qpos[self.qpos_adr] = q_start
        self.controller.hold(q_start)
        mujoco.mj_forward(model, self.data)
        cam = settings.camera
        self.renderer = OffscreenRenderer(
            model,
            cam.width_px,
            cam.height_px,
            shadows=settings.scene.shadows,
            blur_sigma_px=cam.blur_sigma_px,
        )
        self._rng = rng
        self.intrinsics = calibrated_intrinsics(cam, settings.sensor, rng)
        self.measurement, self.fruit_prior = declared_noise(settings)
        self.noise = noise
        if noise is None and settings.filter.state == "centre_radius":
            self.noise = detector_noise_model(settings)
        self.detector = detector if detector is not None else self._settings_detector()
        self._target = np.asarray(target, dtype=float).copy()
        self._keep_images = keep_images
        self._on_step = on_step
        self.last = _Last()
        self._unmeasured: list[Sighting] = []
        self.basket = Basket(model, info)  # the fruit picked (tracking.pick_rounds)

    def _settings_detector(self) -> Detector:
        """The detector ``detector.kind`` names; synthetic boxes get their own stream (spawned
        from the sensor's seed, so the sensor noise stays what it is with the built-in)."""
        s = self.settings
        if s.detector.kind == "builtin":
            return detector_from_settings(s.detector, self.fruit_prior, self.measurement)
        seed = self._rng.bit_generator.seed_seq
        box_rng = np.random.default_rng(
            seed.spawn(1)[0] if isinstance(seed, np.random.SeedSequence) else self._rng.integers(2**63)
        )
        return detector_from_settings(
            s.detector,
            self.fruit_prior,
            self.measurement,
            true_boxes=self.true_boxes,
            image_size_px=(s.camera.width_px, s.camera.height_px),
            rng=box_rng,
        )

    def true_boxes(self) -> np.ndarray:
        """The true bounding boxes (n, 4) [px, not clipped] of the ripe fruit visible in the
        current view, as the rendered camera sees them (:func:`bve_mj.sim.true_boxes.true_boxes`)."""
        s = self.settings
        return true_boxes(self.model, self.data, self.info, s.camera, s.detector.ripe_class)

    # ------------------------------------------------------------------ state
    @property
    def q(self) -> np.ndarray:
        """True joint angles [rad] (for logs and checks; the filter never sees them)."""
        return self.data.qpos[self.qpos_adr].copy()

    @property
    def p_world_fruit(self) -> np.ndarray:
        return self.info.target.centre_m.copy()

    def _measured_pose(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        q_enc = noisy_encoders(self.q, self.settings.sensor, self._rng)
        p, R = self.kin.camera_pose(q_enc)
        return q_enc, p, R

    @property
    def p_world_camera(self) -> np.ndarray:
        """The camera position as the encoders (at the last view) and FK report it."""
        q = self.last.q_encoders if self.last.q_encoders is not None else self.q
        return self.kin.camera_pose(q)[0]

    @property
    def q_measured(self) -> np.ndarray | None:
        """The joint angles the encoders read at the last view [rad] (None before one)."""
        return None if self.last.q_encoders is None else self.last.q_encoders.copy()

    def hold(self, plan: ViewPlan) -> None:
        """A move whose IK failed: the arm stays where it is (holding its position); the
        camera's next target is the plan's."""
        self.last = _Last(ik_failed=True)
        self._target = np.asarray(plan.p_world_target, dtype=float).copy()

    def set_step_hook(self, hook: Callable[[float], None] | None) -> None:
        """Call ``hook(sim_time)`` after every physics step of the moves that follow (None:
        no hook; it replaces the ``on_step`` given at construction)."""
        self._on_step = hook

    # ------------------------------------------------------------------ World
    def move_camera(self, plan: ViewPlan) -> None:
        self.last = _Last()
        t0 = time.perf_counter()
        q_target = plan.q
        if q_target is None:
            upright = IkOptions(upright=self.settings.planner.upright > 0.0)
            ik = look_at_ik(self.kin, plan.p_world_camera, plan.p_world_target, self.q, self._rng, upright)
            q_target = ik.q if ik.success else None
            self.last.ik_failed = not ik.success
        t1 = time.perf_counter()
        timings = self.last.timings
        hook = self._on_step
        if hook is not None:

            def timed(sim_time: float) -> None:
                t = time.perf_counter()
                hook(sim_time)
                timings.record_s += time.perf_counter() - t

        if q_target is not None:  # an IK failure keeps the arm where it is
            self.last.move = self.controller.move_to(q_target, None if hook is None else timed)
        self._target = np.asarray(plan.p_world_target, dtype=float).copy()
        timings.ik_s = t1 - t0
        timings.control_s = time.perf_counter() - t1 - timings.record_s

    def _capture(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        """Render the eye-in-hand image (with the sensor's noise), then read the encoders:
        (image, camera position, camera rotation as the encoders report them, the time the
        capture began [s, perf_counter]); the render time is recorded."""
        t0 = time.perf_counter()
        image = noisy_image(self.renderer.render(self.data, CAMERA_NAME), self.settings.sensor, self._rng)
        self.last.timings.render_s = time.perf_counter() - t0
        q_enc, p, R = self._measured_pose()
        self.last.q, self.last.q_encoders = self.q, q_enc
        if self._keep_images:
            self.last.image = image
        return image, p, R, time.perf_counter()

    def observe(self, belief: Belief | None = None) -> Observation | None:
        image, p, R, t1 = self._capture()
        s = self.settings
        if belief is not None:  # the estimate picks its fruit among those in view, in 3-D
            b = belief.position
            prediction = Prediction(R.T @ (b.mean - p), R.T @ b.cov @ R)
            request = DetectionRequest(self.intrinsics, prediction=prediction, up_camera=R.T[:, 2])
        else:
            ahead = R.T @ (self._target - p)
            predicted = self.intrinsics.project(ahead) if ahead[0] > 1e-3 else None
            request = DetectionRequest(self.intrinsics, predicted_px=predicted)
        det = self.detector.detect(image, request)
        self.last.detection = det
        self.last.timings.detect_s = time.perf_counter() - t1
        if not isinstance(det, Detection):
            return None
        if self.noise is not None:  # the radius in the state: what the detector measures
            z, cov = measure(det, self.noise, s.fruit.shape_index, self.intrinsics.focal_px)
            # encoder noise turns the camera (about 6 joints' errors): a white bearing error
            enc = np.diag([(2.5 * s.sensor.encoder_noise_rad) ** 2] * 2 + [0.0])
            cov += enc
            self.last.measurement = (z, cov)
            outline = detected_outline(det)
            if s.measurement.kind in ("camera", "auto"):
                sensor = enc if s.sensor.encoder_noise_rad > 0.0 else None
                return Observation(z, BearingSizeModel(p, R, cov), outline, sensor)
            return Observation(z[2:], SizeModel(p, float(cov[2, 2])), outline)
        if s.measurement.kind in ("camera", "auto"):  # auto: the camera here
            return Observation(det.p_camera, CameraModel(p, R, det.cov_camera))
        var = float(det.bearing_camera @ det.cov_camera @ det.bearing_camera)
        return Observation(np.array([det.range_m]), RangeModel(p, var))

    def observe_all(self) -> tuple[list[Sighting], BearingSizeModel]:
        """Every ripe fruit in view, each measured as the radius state's camera measurement
        (bearing of the centre and apparent angular radius, the calibrated noise); and a model
        at this view's camera pose (as the encoders report it) for visibility predictions."""
        if self.noise is None:
            raise ValueError("every fruit is measured with the radius in the state (centre_radius)")
        if not isinstance(self.detector, EveryFruitDetector):
            raise ValueError(
                "every fruit is measured by a detector with detect_all; "
                f"{type(self.detector).__name__} has none"
            )
        image, p, R, t1 = self._capture()
        s = self.settings
        found = self.detector.detect_all(
            image, DetectionRequest(self.intrinsics, up_camera=R.T[:, 2]), max_range_m=s.tracking.max_range_m
        )
        self.last.every = found
        self.last.timings.detect_s = time.perf_counter() - t1
        sightings = []
        for det in found.detections:
            z, cov = measure(det, self.noise, s.fruit.shape_index, self.intrinsics.focal_px)
            enc = np.diag([(2.5 * s.sensor.encoder_noise_rad) ** 2] * 2 + [0.0])  # as in observe
            sensor = enc if enc.any() else None
            sightings.append(Sighting(z, BearingSizeModel(p, R, cov + enc), sensor, detected_outline(det)))
        self._unmeasured = []
        for r in found.refused:
            if r.partial and r.centre_px is not None and r.radius_px is not None:
                ray = self.intrinsics.rays(r.centre_px)[0]
                weak = unmeasured_sighting(ray, r.radius_px, self.intrinsics.focal_px, p, R)
                if weak is not None:
                    self._unmeasured.append(weak)
        return sightings, BearingSizeModel(p, R, np.eye(3) * 1e-8)

    def unmeasured(self) -> list[Sighting]:
        """The fruit the last :meth:`observe_all` found but saw only in part, as weak sightings
        (:func:`~bve_mj.estimation.unmeasured.unmeasured_sighting`)."""
        return list(self._unmeasured)

    def view_info(self) -> dict[str, Any]:
        """What happened in the last view, JSON-ready."""
        last = self.last
        det = last.detection
        out: dict[str, Any] = {
            "q_rad": None if last.q is None else last.q.tolist(),
            "q_encoders_rad": None if last.q_encoders is None else last.q_encoders.tolist(),
            "ik_failed": last.ik_failed,
            "timings_s": vars(last.timings).copy(),
        }
        if last.q_encoders is not None:
            p, R = self.kin.camera_pose(last.q_encoders)
            out["camera_position_m"], out["camera_rotation"] = p.tolist(), R.tolist()
        if last.move is not None:
            out["move"] = vars(last.move).copy()
        if isinstance(det, Detection):
            out["detection"] = {
                "centre_px": det.centre_px.tolist(),
                "radius_px": det.radius_px,
                "bearing_camera": det.bearing_camera.tolist(),
                "angular_radius_rad": det.angular_radius_rad,
                "range_m": det.range_m,
                "p_camera_m": det.p_camera.tolist(),
                "cov_camera_m2": det.cov_camera.tolist(),
                "trimmed_fraction": det.trimmed_fraction,
                "arc_deg": det.arc_deg,
                "neighbour_share": det.neighbour_share,
                "centre_fit_px": det.centre_fit_px,
                "radius_fit_px": det.radius_fit_px,
            }
            if last.measurement is not None:  # the radius in the state: (u, v, α) and R as fused
                z, cov = last.measurement
                out["measurement"] = {"z": z.tolist(), "cov": cov.tolist()}
        elif isinstance(det, NoDetection):
            out["detection"] = {"none": det.reason}
            if det.ambiguous:
                out["events"] = ["ambiguous"]
            if det.candidates and last.q_encoders is not None:  # in the frame the filter fuses in
                p, R = self.kin.camera_pose(last.q_encoders)
                out["ambiguous_candidates"] = [
                    {"p_world_m": (p + R @ z).tolist(), "cov_world_m2": (R @ C @ R.T).tolist()}
                    for z, C in det.candidates
                ]
        if last.every is not None:
            out["detections"] = [
                {"centre_px": d.centre_px.tolist(), "radius_px": d.radius_px, "arc_deg": d.arc_deg}
                for d in last.every.detections
            ]
            out["refused"] = len(last.every.refused)
        return out

    @property
    def picked(self) -> tuple[str, ...]:
        """The fruit taken off the plant so far (:meth:`pick`), by name, in order."""
        return self.basket.names

    def pick(self, name: str) -> None:
        """Take fruit ``name`` off the plant, with its calyx (:meth:`Basket.take`); :meth:`close`
        puts it back in the compiled scene, which the process's episodes share.

        Raises:
            KeyError: when the scene has no fruit ``name``, or it was picked already."""
        self.basket.take(name)
        mujoco.mj_forward(self.model, self.data)

    def close(self) -> None:
        self.basket.put_back()
        self.renderer.close()
