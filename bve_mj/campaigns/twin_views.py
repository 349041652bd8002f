"""Twin views: how the detector's errors in two views of a fruit correlate with the distance
between the two cameras.

The calibration's views (:func:`bve_mj.campaigns.calibration.sample_views`) are drawn at
random around the fruit: hardly two of them are taken from one place, so the correlation
they measure (:func:`~bve_mj.estimation.view_correlation.fit_view_correlation`, by the angle
between the views) says nothing of what the loop does when its camera holds: a view from
where the last one was sees the same pixels of the same silhouette. Here each drawn view
(a look-at view of the target from a pose the arm reaches, as the calibration draws them)
gets twins: the same aim from a camera displaced by δ (0, 2, 5 ... 40 mm) across the
viewing direction. The errors of a view and its twin (bearing u and v, apparent radius;
the radius' linear bias in the apparent size removed) give, per δ, a correlation that
outlying fits do not decide (over the pairs both of whose errors lie within 3 robust σ of
their component), and :func:`fit_nearby` fits the part of the nugget that nearby views share
(:class:`~bve_mj.estimation.view_correlation.ViewCorrelation` ``nearby``, ``length_m``).

Frames: world (robot base); errors in pixels of the camera's image.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace
from typing import Any, NamedTuple

import numpy as np

from bve_mj.estimation.noise import NoiseModel
from bve_mj.estimation.view_correlation import ViewCorrelation

__all__ = [
    "DELTAS_M", "TwinCorrelation", "fit_nearby", "fit_twins", "sample_twins", "twin_correlations",
    "twin_rows",
]  # fmt: skip

DELTAS_M = (0.0, 0.002, 0.005, 0.01, 0.02, 0.04)
"""The displacements of a view's twins [m]."""

_AIM_SIGMA_M = 0.002
_ATTEMPTS = 8
_LOG_LENGTH = (math.log(1e-4), 0.0)  # the kernel's length searched [ln m]


def sample_twins(
    name: str, settings: Any, scene_seed: int, views: int, deltas_m: Sequence[float] = DELTAS_M
) -> list[dict[str, Any]]:
    """``views`` drawn views of the target of one seeded scene and their twins (one per δ in
    ``deltas_m``), detected: one row per twin whose view and itself measured the target,
    with the two views' errors (u, v, α) [px], the base view's apparent radius [px], δ and
    the cosine of the angle between the two viewing directions."""
    import mujoco

    from bve_mj.campaigns.calibration import _detection_fields
    from bve_mj.campaigns.view_draws import calibration_scene, draw_direction
    from bve_mj.perception.detection import Detection, Prediction
    from bve_mj.perception.detector import detect
    from bve_mj.robot import IkOptions, look_at_ik
    from bve_mj.sim.arm import CAMERA_NAME
    from bve_mj.sim.sensors import noisy_image

    rng, kin, info, model, data, adr, intrinsics, measurement, fruit, renderer = calibration_scene(
        settings, scene_seed
    )
    truth, radius = info.target.centre_m, info.target.radius_m
    q_seed = kin.home.copy()

    def shot(c: np.ndarray, aim: np.ndarray) -> tuple[np.ndarray, np.ndarray, float] | None:
        ik = look_at_ik(kin, c, aim, q_seed, rng, IkOptions(restarts=2))
        if not ik.success:
            return None
        data.qpos[adr] = ik.q
        mujoco.mj_forward(model, data)
        image = noisy_image(renderer.render(data, CAMERA_NAME), settings.sensor, rng)
        p, R = kin.camera_pose(ik.q)
        prediction = Prediction(R.T @ (aim - p), np.eye(3) * _AIM_SIGMA_M**2)
        det = detect(
            image, intrinsics, fruit, measurement, settings.detector,
            prediction=prediction, up_camera=R.T[:, 2],
        )  # fmt: skip
        if not isinstance(det, Detection):
            return None
        d = _detection_fields(det, R.T @ (truth - p), radius, settings.camera.focal_px)
        return p, np.array([d["err_u_px"], d["err_v_px"], d["err_alpha_px"]]), float(det.radius_px)

    rows: list[dict[str, Any]] = []
    try:
        taken = attempts = 0
        while taken < views and attempts < _ATTEMPTS * views:
            attempts += 1
            direction, rho = draw_direction(rng)
            aim = truth + rng.normal(0.0, _AIM_SIGMA_M, 3)
            base = shot(truth + rho * direction, aim)
            if base is None:
                continue
            taken += 1
            p0, e0, r0 = base
            d0 = (p0 - truth) / np.linalg.norm(p0 - truth)
            for delta in deltas_m:
                across = rng.normal(size=3)
                across -= (across @ direction) * direction
                twin = shot(p0 + delta * across / np.linalg.norm(across), aim)
                if twin is None:
                    continue
                p1, e1, _ = twin
                d1 = (p1 - truth) / np.linalg.norm(p1 - truth)
                rows.append({
                    "scenario": name, "scene_seed": scene_seed, "delta_m": float(delta),
                    "cos": float(d0 @ d1), "errors": e0.tolist(), "twin_errors": e1.tolist(), "radius_px": r0,
                })  # fmt: skip
    finally:
        renderer.close()
    return rows


def _scaled(x: np.ndarray) -> np.ndarray:
    """``x`` less its median, in robust σ (MAD)."""
    mid = float(np.median(x))
    sigma = 1.4826 * float(np.median(np.abs(x - mid)))
    return (x - mid) / max(sigma, 1e-12)


def _correlation(a: np.ndarray, b: np.ndarray) -> float:
    """The correlation of the pairs both of whose errors lie within 3 robust σ: a gross error
    (a fit on a neighbour's edge) of one view would otherwise decide it, or halve it."""
    a, b = _scaled(a), _scaled(b)
    kept = (np.abs(a) <= 3.0) & (np.abs(b) <= 3.0)
    return float(np.corrcoef(a[kept], b[kept])[0, 1])


class TwinCorrelation(NamedTuple):
    """The twins of one displacement: δ [m], the pairs, the mean cosine of the angle between
    a view's and its twin's directions, and the robust correlations of their errors."""

    delta_m: float
    pairs: int
    cos: float
    centre: float
    radius: float


def twin_correlations(rows: Sequence[dict[str, Any]]) -> list[TwinCorrelation]:
    """Per δ: the robust correlation of a view's errors and its twin's, the bearing's (u and
    v pooled) and the apparent radius' (its linear bias in the apparent size removed)."""
    e0 = np.array([r["errors"] for r in rows], dtype=float).reshape(-1, 3)
    e1 = np.array([r["twin_errors"] for r in rows], dtype=float).reshape(-1, 3)
    size = np.array([r["radius_px"] for r in rows], dtype=float)
    A = np.column_stack((np.ones(len(size)), size))
    bias = np.linalg.lstsq(np.vstack((A, A)), np.r_[e0[:, 2], e1[:, 2]], rcond=None)[0]
    e0[:, 2] -= A @ bias
    e1[:, 2] -= A @ bias
    delta = np.array([r["delta_m"] for r in rows], dtype=float)
    cos = np.array([r["cos"] for r in rows], dtype=float)
    out = []
    for d in sorted(set(delta.tolist())):
        m = delta == d
        if m.sum() < 10:
            continue
        centre = _correlation(np.r_[e0[m, 0], e0[m, 1]], np.r_[e1[m, 0], e1[m, 1]])
        radius = _correlation(e0[m, 2], e1[m, 2])
        out.append(TwinCorrelation(d, int(m.sum()), float(cos[m].mean()), centre, radius))
    return out


def fit_nearby(table: Sequence[TwinCorrelation], corr: ViewCorrelation, component: str) -> ViewCorrelation:
    """``corr`` (its directional part as fitted) with the nearby part fitted to the twins'
    correlations of ``component`` (``centre`` or ``radius``): least squares over (a, ℓ),
    weighted by the pairs, of
    ρ(δ) = w exp(-(1 - cos θ)/s) + (1 - w) a (1 + √3 δ/ℓ) exp(-√3 δ/ℓ)."""
    from scipy.optimize import minimize

    if len(table) < 3:
        raise ValueError(f"{len(table)} displacements with enough pairs: at least 3 are needed")
    if component not in ("centre", "radius"):
        raise ValueError(f"component must be centre or radius, got {component!r}")
    delta = np.array([t.delta_m for t in table])
    n = np.array([t.pairs for t in table], dtype=float)
    direct = corr.rho(np.array([t.cos for t in table]))
    observed = np.array([getattr(t, component) for t in table])

    def model(p: np.ndarray) -> tuple[float, float, np.ndarray]:
        a = 0.99 / (1.0 + math.exp(-min(max(p[0], -30.0), 30.0)))
        length = math.exp(min(max(p[1], _LOG_LENGTH[0]), _LOG_LENGTH[1]))  # 0.1 mm to 1 m: a few pairs
        x = math.sqrt(3.0) * delta / length
        return a, length, direct + (1.0 - corr.weight) * a * (1.0 + x) * np.exp(-x)

    def loss(p: np.ndarray) -> float:
        return float(np.sum(n * (observed - model(p)[2]) ** 2))

    starts = [np.array([a0, math.log(l0)]) for a0 in (0.0, 2.0) for l0 in (0.005, 0.02, 0.05)]
    best = min((minimize(loss, x0, method="Nelder-Mead") for x0 in starts), key=lambda r: r.fun)
    a, length, _ = model(best.x)
    return replace(corr, nearby=round(a, 4), length_m=round(length, 5))


def _twin_task(task: tuple[str, Any, int, int]) -> list[dict[str, Any]]:
    from bve_mj.threads import one_blas_thread

    with one_blas_thread():
        return sample_twins(*task)


def twin_rows(
    scenarios: Sequence[Any], *, scenes: int, views: int, seed: int, workers: int
) -> list[dict[str, Any]]:
    """:func:`sample_twins` of ``views`` drawn views of each of ``scenes`` seeded scenes of
    every scenario (``scenarios``: :class:`~bve_mj.campaigns.spec.Scenario`; the scenes the
    calibration's seed ``seed`` draws), in ``workers`` spawned processes."""
    from bve_mj.campaigns.executors import local_batches
    from bve_mj.campaigns.spec import episode_seed

    tasks = [
        (sc.name, sc.settings("camera"), episode_seed(seed, k), views)
        for sc in scenarios
        for k in range(scenes)
    ]
    return [r for batch in local_batches(_twin_task, tasks, max(1, min(workers, len(tasks)))) for r in batch]


def fit_twins(
    model: NoiseModel,
    scenarios: Sequence[Any],
    *,
    scenes: int,
    views: int,
    seed: int,
    workers: int,
) -> tuple[NoiseModel, list[TwinCorrelation], int]:
    """``model`` with the nearby part of both correlations fitted (:func:`fit_nearby`) to the
    twins of :func:`twin_rows`; with the table of correlations and the pairs. Too few pairs
    (fewer than three displacements with ten): ``model`` as it is (nearby views counted by
    their directions)."""
    rows = twin_rows(scenarios, scenes=scenes, views=views, seed=seed, workers=workers)
    table = twin_correlations(rows) if rows else []
    if len(table) < 3:
        return model, table, len(rows)
    centre = fit_nearby(table, model.centre_correlation, "centre")
    radius = fit_nearby(table, model.radius_correlation, "radius")
    source = f"{model.source}; nearby views from {len(rows)} twin pairs ({views} views a scene)"
    fitted = replace(model, centre_correlation=centre, radius_correlation=radius, source=source)
    return fitted, table, len(rows)
