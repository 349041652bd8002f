"""Noise calibration: the detector against ground truth, over the scenes it will meet.

For each scenario of the suite (or any scenario files) and each of ``scenes`` seeded scenes
of it, the arm takes ``views`` look-at poses around the target (the pose sampler below),
the eye-in-hand image is rendered and the detector measures, given a prediction of the
target as the closed loop gives it (its mean a few millimetres off the truth, its
covariance saying so). Every detection is compared with the truth: the error of the
bearing of the centre (the two normalised image coordinates) and of the apparent
(equatorial) angular radius, in pixels (f · angle), beside what the detector saw (apparent
radius, share of the outline, trimmed share, the fit's own σ and the arcs' jackknife
spread). With ``every_fruit`` (``bve-mj calibrate --every-fruit``), the every-fruit detector
(``--fruits all``) measures the same image too: each neighbour of the target it measured or
refused is a row, matched to the true fruit (``fruit``, its index in the
scene; ``source: "every"``): the fruit beside the target that ``--fruits all`` fuses too
(seen off the optical axis, behind and between their neighbours, of every ripeness the mask
takes), which the target's views alone never sample. The model is fitted to the target's
rows; the neighbours' rows fit the views' tail (:mod:`bve_mj.estimation.outliers`), which the
every-fruit tracker fuses with (pooled into the model itself, they changed nothing on
held-out seeds: docs/honesty.md, "Calibrating what the every-fruit filter fuses").
:func:`bve_mj.estimation.noise_fit.fit_noise_model`
turns the samples into the noise model the filter uses, each fruit's rows its own
(:func:`bve_mj.estimation.noise_tail.fruit_key`).

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
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from bve_mj.campaigns.scenarios import Scenario
from bve_mj.campaigns.view_draws import calibration_scene, draw_direction
from bve_mj.errors import ConfigError
from bve_mj.estimation.noise import NoiseModel
from bve_mj.estimation.noise_fit import fit_noise_model, split_gross
from bve_mj.estimation.partial_colour import fit_partial_colour

if TYPE_CHECKING:
    from bve_mj.perception.all_fruit import FruitDetections
    from bve_mj.perception.detection import Detection, Intrinsics
    from bve_mj.sim.scene_model import Fruit

__all__ = [
    "CalibrationData",
    "FruitImage",
    "calibrate",
    "fruit_images",
    "matched_fruit",
    "run_calibration",
    "sample_views",
]

_AIM_SIGMA_M = (0.0005, 0.008)  # the loop's estimate error when it looks (its σ drawn here)
_ATTEMPTS = 8  # candidate poses tried per view asked for (the arm reaches about a third)


def sample_views(
    name: str, settings: Any, scene_seed: int, views: int, every_fruit: bool = False
) -> list[dict[str, Any]]:
    """Render ``views`` look-at views of the target of one seeded scene of ``settings``
    (closed-loop settings of a scenario) and detect it in each: one row per view that
    the arm could take, with the detector's answer and the truth. With ``every_fruit``,
    also one row per fruit the every-fruit detector (``--fruits all``) measured in the same
    image, matched to the true fruit it measured (``fruit``: its index in the scene), but
    the target: its own rows measure it."""
    import mujoco

    from bve_mj.perception.all_fruit import detect_all
    from bve_mj.perception.detection import Detection, Prediction
    from bve_mj.perception.detector import detect
    from bve_mj.robot import IkOptions, look_at_ik
    from bve_mj.sim.arm import CAMERA_NAME
    from bve_mj.sim.sensors import noisy_image

    rng, kin, info, model, data, adr, intrinsics, measurement, fruit, renderer = calibration_scene(
        settings, scene_seed
    )
    f = settings.camera.focal_px
    target = info.target
    truth = target.centre_m
    rows: list[dict[str, Any]] = []
    q_seed = kin.home.copy()
    try:
        view, attempts = 0, 0
        while view < views and attempts < _ATTEMPTS * views:  # about a third are reachable
            attempts += 1
            direction, rho = draw_direction(rng)
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
                "ripe_class": settings.detector.ripe_class or "red",
                "fruit_shape_index": fruit.shape_index,
                "camera_position_m": p.tolist(),
                "camera_rotation": R.tolist(),
                "truth_m": truth.tolist(),
            }
            if isinstance(det, Detection):
                row.update(_detection_fields(det, t, target.radius_m, f))
            else:
                row.update(detected=False, reason=det.reason)
            rows.append(row)
            if every_fruit:
                found = detect_all(
                    image, intrinsics, fruit, measurement, settings.detector,
                    up_camera=R.T[:, 2], max_range_m=settings.tracking.max_range_m,
                )  # fmt: skip
                rows += _every_fruit_rows(found, info.fruits, p, R, intrinsics, row, exclude=0)
    finally:
        renderer.close()
    return rows


def _detection_fields(
    det: Detection, t_camera: np.ndarray, radius_m: float, focal_px: float
) -> dict[str, Any]:
    """What the detector saw of a fruit whose centre lies at ``t_camera`` [m] (camera frame)
    and its errors against the truth: bearing (u, v) and apparent angular radius, in px."""
    a = det.bearing_camera
    t = t_camera
    alpha_true = math.asin(min(radius_m / float(np.linalg.norm(t)), 1.0))
    return {
        "detected": True,
        "radius_px": det.radius_px,
        "arc_deg": det.arc_deg,
        "trimmed_fraction": det.trimmed_fraction,
        "centre_fit_px": det.centre_fit_px,
        "radius_fit_px": det.radius_fit_px,
        "centre_jackknife_px": det.centre_jackknife_px,
        "radius_jackknife_px": det.radius_jackknife_px,
        "neighbour_share": det.neighbour_share,
        "centre_disagreement_px": det.centre_disagreement_px,
        "err_u_px": float(focal_px * (a[1] / a[0] - t[1] / t[0])),
        "err_v_px": float(focal_px * (a[2] / a[0] - t[2] / t[0])),
        "err_alpha_px": float(focal_px * (det.angular_radius_rad - alpha_true)),
    }


MATCH_RADII = 0.5
"""A detection (or refusal) is of the fruit whose centre's image lies this many of its apparent
radii from the detection's centre, or nearer; one farther from every fruit is of none."""


class FruitImage(NamedTuple):
    """A true fruit ahead of the camera, as the camera sees it."""

    fruit_index: int  # in the list of fruit given
    fruit: Fruit
    t_camera_m: np.ndarray  # its centre in the camera frame (x optical axis), (3,)
    distance_m: float
    centre_px: np.ndarray  # the image of its centre, (2,)
    radius_px: float  # its apparent radius


def fruit_images(
    fruits: Sequence[Fruit], p_world_camera: np.ndarray, R_world_camera: np.ndarray, intrinsics: Intrinsics
) -> list[FruitImage]:
    """The fruit ahead of the camera (centre more than a radius in front of it), as it sees them."""
    out = []
    for i, fr in enumerate(fruits):
        t = R_world_camera.T @ (fr.centre_m - p_world_camera)
        dist = float(np.linalg.norm(t))
        if t[0] <= fr.radius_m or dist <= fr.radius_m:
            continue
        r_px = intrinsics.focal_px * math.tan(math.asin(fr.radius_m / dist))
        out.append(FruitImage(i, fr, t, dist, intrinsics.project(t), r_px))
    return out


def matched_fruit(centre_px: np.ndarray, images: Sequence[FruitImage]) -> FruitImage | None:
    """The fruit a detection centred at ``centre_px`` [px] is of: the one whose centre's image
    lies nearest, in its apparent radii, within :data:`MATCH_RADII`; None where none does."""
    if not images:
        return None
    best = min(images, key=lambda m: float(np.linalg.norm(centre_px - m.centre_px)) / m.radius_px)
    return best if float(np.linalg.norm(centre_px - best.centre_px)) <= MATCH_RADII * best.radius_px else None


def _every_fruit_rows(
    found: FruitDetections,
    fruits: Sequence[Fruit],
    p_world_camera: np.ndarray,
    R_world_camera: np.ndarray,
    intrinsics: Intrinsics,
    view_row: dict[str, Any],
    *,
    exclude: int | None = None,
) -> list[dict[str, Any]]:
    """The every-fruit detector's answer in one view (``found``: its
    :class:`~bve_mj.perception.all_fruit.FruitDetections`) as rows: one per detection matched
    to the true fruit it measured (:func:`matched_fruit`), and one ``detected: False`` row per
    fruit that view refused (seen in part, a poor fit ...) and did not measure: the refusal scale needs each
    fruit's refused share. The view's own fields (scenario, scene, camera) from ``view_row``.
    A detection or refusal of fruit ``exclude`` (the target, which its own rows measure) is
    matched but gives no row: a scene of one fruit would otherwise count it twice."""
    f = intrinsics.focal_px
    seen = fruit_images(fruits, p_world_camera, R_world_camera, intrinsics)

    view = {k: view_row[k] for k in ("scenario", "scene_seed", "view", "aim_sigma_m", "fruit_shape_index",
                                     "camera_position_m", "camera_rotation")}  # fmt: skip
    view["ripe_class"] = view_row.get("ripe_class", "red")

    def fruit_fields(i: int, fr: Fruit, t: np.ndarray, dist: float) -> dict[str, Any]:
        return {
            **view, "source": "every", "fruit": i, "distance_m": dist,
            "off_axis_px": float(f * math.hypot(t[1], t[2]) / t[0]), "true_radius_m": fr.radius_m,
            "shape_index": fr.shape_index, "colour": fr.colour, "truth_m": fr.centre_m.tolist(),
        }  # fmt: skip

    rows: list[dict[str, Any]] = []
    measured: set[int] = set()
    refused: set[int] = set()
    for det in found.detections:
        m = matched_fruit(det.centre_px, seen)
        if m is not None and m.fruit_index != exclude:
            i, fr, t, dist, _, _ = m
            rows.append({**fruit_fields(i, fr, t, dist), **_detection_fields(det, t, fr.radius_m, f)})
            measured.add(i)
    for ref in found.refused:
        m = None if ref.centre_px is None else matched_fruit(ref.centre_px, seen)
        if m is not None and m.fruit_index not in measured | refused and m.fruit_index != exclude:
            i, fr, t, dist, _, _ = m
            rows.append({**fruit_fields(i, fr, t, dist), "detected": False, "reason": ref.reason})
            refused.add(i)
    return rows


Task = tuple[str, Any, int, int, bool]


def _run_task(task: Task) -> list[dict[str, Any]]:
    from bve_mj.threads import one_blas_thread

    name, settings, scene_seed, views, every_fruit = task
    with one_blas_thread():
        return sample_views(name, settings, scene_seed, views, every_fruit)


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
    every_fruit: bool = False,
    drawn: Sequence[Scenario] = (),
) -> CalibrationData:
    """``views`` views of ``scenes`` seeded scenes of every scenario, and of one scene of each
    ``drawn`` scenario (configurations drawn at random, :mod:`bve_mj.campaigns.drawn_scenes`:
    each is its own configuration, so one scene of each spreads the views over more of
    them), in spawned workers (with ``every_fruit``, the every-fruit detector's rows too:
    :func:`sample_views`)."""
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
        (sc.name, sc.settings("camera"), episode_seed(seed, k), views, every_fruit)
        for sc in scenarios
        for k in range(scenes)
    ] + [(sc.name, sc.settings("camera"), episode_seed(seed, 0), views, every_fruit) for sc in drawn]
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
    every_fruit: bool = False,
    drawn: Sequence[Scenario] = (),
    twin_views: int = 2,
) -> tuple[NoiseModel, dict[str, Any], CalibrationData]:
    """Render and detect (:func:`run_calibration`), then fit the noise model
    (:func:`~bve_mj.estimation.noise_fit.fit_noise_model`) and, from ``twin_views`` views of
    each scene and their twins, the part nearby views share
    (:func:`~bve_mj.campaigns.twin_views.fit_twins`; 0: none), and last what a detector of a
    class short of red errs beyond the rest (:func:`~bve_mj.estimation.partial_colour.
    fit_partial_colour`, from the rows of such detectors): the model, how well it describes
    the samples, and the samples. The default seed (1) keeps the scenario suite's episodes
    (seeds 0 and 7777 there) out of the calibration."""
    from bve_mj.campaigns.twin_views import fit_twins

    data = run_calibration(
        scenarios, scenes=scenes, views=views, seed=seed, workers=workers, progress=progress,
        every_fruit=every_fruit, drawn=drawn,
    )  # fmt: skip
    camera = scenarios[0].settings("camera").camera
    for sc in [*scenarios[1:], *drawn]:
        if sc.settings("camera").camera != camera:
            raise ConfigError(
                "scenarios", sc.name, "scenarios that share one camera (the model is per camera)"
            )
    names = ",".join(data.scenarios)
    source = f"bve-mj calibrate: scenarios {names}; {scenes} scenes x {views} views each, seed {seed}"
    if drawn:
        source += f"; {len(drawn)} drawn scenes ({drawn[0].name}, ...), one scene each"
    if every_fruit:
        source += "; every fruit"
    target = [r for r in data.rows if r.get("source") != "every"]
    every = [r for r in data.rows if r.get("source") == "every"]
    # the model is the target's (its refusals fit the refusal scale); the neighbours' rows, what
    # the every-fruit tracker fuses with it, fit the views' tail
    model, report = fit_noise_model(target, camera, source, every or None)
    report["views"] = len(target)
    report["refused"] = sum(not r.get("detected") for r in target)
    report["every_fruit_detections"] = sum(bool(r.get("detected")) for r in every)
    report["every_fruit_refused"] = len(every) - report["every_fruit_detections"]
    if twin_views:
        cores = workers if workers is not None else os.cpu_count() or 1
        model, table, pairs = fit_twins(
            model, scenarios, scenes=scenes, views=twin_views, seed=seed, workers=cores
        )
        report["twins"] = {"views": twin_views, "pairs": pairs, "table": [t._asdict() for t in table]}
    # last, under the rest: what a detector of a class short of red errs beyond it (none from
    # too few such rows: the suite's own scenes render two or three such fruits)
    kept = split_gross(target, camera)[0]
    model, views_short, fruits_short = fit_partial_colour(kept, model, camera.focal_px)
    report["partial_colour"] = {"views": views_short, "fruits": fruits_short}
    return model, report, data
