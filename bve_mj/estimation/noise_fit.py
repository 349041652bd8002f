"""Fitting the detector's noise model to calibration rows (``bve-mj calibrate``): maximum
likelihood variances and the radius bias, each fruit's own centre offset and its bound, and
the correlation of views from nearby directions; the fit's report."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from bve_mj.config import CameraConfig
from bve_mj.errors import ConfigError
from bve_mj.estimation.noise import OFFSET_FEATURES, NoiseModel, Outline
from bve_mj.estimation.noise_tail import FruitKey, fit_claim_shape, fruit_key, row_sigmas
from bve_mj.estimation.outliers import OutlierMixture, fit_outlier_mixture
from bve_mj.estimation.view_correlation import ViewCorrelation, fit_view_correlation

__all__ = [
    "GROSS_SIGMAS",
    "fit_noise_model",
    "fruit_offsets",
    "noise_report",
    "seen_outlines",
    "split_gross",
    "within_gross",
    "without_offsets",
]


def fit_noise_model(
    rows: Sequence[dict[str, Any]],
    camera: CameraConfig,
    source: str = "",
    outlier_rows: Sequence[dict[str, Any]] | None = None,
) -> tuple[NoiseModel, dict[str, Any]]:
    """Fit :class:`NoiseModel` to calibration rows (detected views: ``radius_px``, ``arc_deg``,
    ``centre_fit_px``, ``radius_fit_px``, ``fruit_shape_index``, ``err_u_px``, ``err_v_px``,
    ``err_alpha_px``) by maximum likelihood (coefficients ≥ 0 through their logarithms); and
    a report: the normalised errors' rms and their share beyond 2σ and 3σ (Gaussian: 4.6%
    and 0.27%).

    Gross errors are fitted apart: a detection more than :data:`GROSS_SIGMAS` σ off under a
    first fit (the wrong fruit picked, a neighbour's outline) is no sample of the noise but a
    failure the filter's gate rejects; the model is fitted again without them and the report
    counts them.

    The views' tail (:mod:`bve_mj.estimation.outliers`) is fitted to every view's own error
    under the model, the gross ones too (a wide belief cannot gate them out), of
    ``outlier_rows`` (default ``rows``): the every-fruit detector's rows, which the tracker
    fuses with this model's σ, where the calibration measured them."""
    det = [r for r in rows if r.get("detected")]
    f = camera.focal_px
    kept, refused = split_gross(rows, camera)
    model = _fit(kept, camera, source)
    # two levels: each fruit's own offset (the same from every view) and each view's own
    # error; the per-view noise is fitted to what is left once the offsets are taken out
    for _ in range(3):
        offsets = fruit_offsets(kept, model, f)
        model = _fit(without_offsets(kept, offsets, f), camera, source)
    offsets = fruit_offsets(kept, model, f)
    model = replace(model, centre_bias_rel=_offset_bound(offsets))
    model = replace(model, centre_offset_terms=_offset_terms(offsets, seen_outlines(kept), model))
    per_view = without_offsets(kept, offsets, f)
    centre_corr, radius_corr = _view_correlations(per_view, model)
    model = replace(model, centre_correlation=centre_corr, radius_correlation=radius_corr)
    refusal, fruits = _refusal_scale([*refused, *kept], model)
    model = replace(model, refusal_scale=refusal)
    model = fit_claim_shape(kept, refused, model, f)
    mixture = _outlier_mixture([r for r in (outlier_rows or rows) if r.get("detected")], model, f)
    model = replace(model, outlier_share=mixture.share, outlier_scale=mixture.scale)
    report = noise_report(per_view, model)
    report["refusal_fruits"] = fruits
    report["gross_errors"] = len(det) - len(kept)
    report["fruits"] = len(offsets)
    return model, report


def split_gross(
    rows: Sequence[dict[str, Any]], camera: CameraConfig
) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """(kept, refused): the detections within :data:`GROSS_SIGMAS` of a first fit to all of
    them, which the model is fitted to, and the views the detector refused."""
    det = [r for r in rows if r.get("detected")]
    if len(det) < 20:
        raise ConfigError("calibration", len(det), "at least 20 detections to fit a noise model")
    return within_gross(det, _fit(det, camera, "")), [r for r in rows if not r.get("detected")]


def within_gross(det: Sequence[dict[str, Any]], model: NoiseModel) -> list[dict[str, Any]]:
    """The detections within :data:`GROSS_SIGMAS` of ``model`` in every component."""
    return [r for r, zc in zip(det, _normalised(det, model), strict=True) if zc <= GROSS_SIGMAS]


def _outlier_mixture(det: Sequence[dict[str, Any]], model: NoiseModel, focal_px: float) -> OutlierMixture:
    """The scale mixture of these detections' own errors under ``model`` (each fruit's offset,
    from its views within :data:`GROSS_SIGMAS`, taken out of all of them)."""
    if not det:
        return OutlierMixture()
    kept = within_gross(det, model)
    own = without_offsets(det, fruit_offsets(kept, model, focal_px), focal_px)
    return fit_outlier_mixture(np.square(_components(own, model).reshape(-1, 3)).sum(axis=1), 3)


GROSS_SIGMAS = 6.0

"""A calibration detection this many σ off (in any component) is a gross error, not noise."""


def _normalised(det: Sequence[dict[str, Any]], model: NoiseModel) -> list[float]:
    """The largest |error| / σ of each detection's three components under ``model``."""
    if not det:
        return []
    return [float(x) for x in np.abs(_components(det, model)).reshape(-1, 3).max(axis=1)]


def _fit(det: Sequence[dict[str, Any]], camera: CameraConfig, source: str) -> NoiseModel:
    from scipy.optimize import minimize

    rp = np.array([r["radius_px"] for r in det], dtype=float)

    def design(fit_key: str) -> np.ndarray:
        def row(r: dict[str, Any]) -> np.ndarray:
            nb = r.get("neighbour_share", 0.0)
            return NoiseModel.features(r["radius_px"], r["arc_deg"], r[fit_key], r["fruit_shape_index"], nb)

        return np.array([row(r) for r in det])

    def fit_var(e: np.ndarray, X: np.ndarray, bias_cols: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        nb = 0 if bias_cols is None else bias_cols.shape[1]

        def nll(p: np.ndarray) -> float:
            # clipped: a term no row shows has no optimum and would run off to inf (inf · 0)
            v = X @ np.exp(np.clip(p[nb:], -60.0, 60.0))
            res = e if bias_cols is None else e - bias_cols @ p[:nb]
            return float(0.5 * np.sum(np.log(v) + res**2 / v))

        p0 = np.concatenate([np.zeros(nb), np.log(np.full(X.shape[1], 0.05))])
        best = minimize(nll, p0, method="L-BFGS-B")
        coef = np.exp(best.x[nb:])
        coef[(coef < 1e-9) | ~X.any(axis=0)] = 0.0  # a term the rows never show says nothing
        return coef, best.x[:nb]

    Xc = design("centre_fit_px")
    e_c = np.concatenate([[r["err_u_px"] for r in det], [r["err_v_px"] for r in det]])
    c_coef, _ = fit_var(e_c, np.vstack([Xc, Xc]), None)
    Xr = design("radius_fit_px")
    e_r = np.array([r["err_alpha_px"] for r in det])
    r_coef, bias = fit_var(e_r, Xr, np.column_stack([np.ones_like(rp), rp / 100.0]))
    return NoiseModel(
        centre_var_px2=tuple(float(x) for x in c_coef),
        radius_var_px2=tuple(float(x) for x in r_coef),
        radius_bias_px=(float(bias[0]), float(bias[1])),
        typical_fit_px=float(np.median([r["centre_fit_px"] for r in det])),
        centre_bias_rel=(0.0, 0.0),
        width_px=camera.width_px,
        height_px=camera.height_px,
        hfov_deg=round(math.degrees(camera.hfov_rad), 6),
        samples=len(det),
        source=source,
    )


def fruit_offsets(
    det: Sequence[dict[str, Any]], model: NoiseModel, focal_px: float
) -> dict[FruitKey, tuple[np.ndarray, np.ndarray, float]]:
    """Each fruit's own world-frame offset of the fitted centre: per fruit (the rows of one
    :func:`fruit_key`, 6 views or more), the weighted least-squares offset b [m] that its
    views' lateral errors (each bearing error times the range, along the camera's y and z
    axes) share, its covariance C from the per-view noise of ``model``, and its radius."""
    groups: dict[FruitKey, list[dict[str, Any]]] = {}
    for r in det:
        if "camera_rotation" in r:
            groups.setdefault(fruit_key(r), []).append(r)
    out = {}
    for key, rows in groups.items():
        if len(rows) < 6:
            continue
        A, b, w = [], [], []
        for r in rows:
            R = np.asarray(r["camera_rotation"], dtype=float)
            sc = row_sigmas(model, r)[0]
            scale = r["distance_m"] / focal_px
            for axis, e in ((1, r["err_u_px"]), (2, r["err_v_px"])):
                A.append(R[:, axis])
                b.append(e * scale)
                w.append(1.0 / (sc * scale) ** 2)
        Am, bm, wm = np.array(A), np.array(b), np.array(w)
        try:
            C = np.linalg.inv(Am.T @ (Am * wm[:, None]))
        except np.linalg.LinAlgError:
            continue
        out[key] = (C @ (Am.T @ (wm * bm)), C, float(rows[0]["true_radius_m"]))
    return out


def without_offsets(
    det: Sequence[dict[str, Any]],
    offsets: dict[FruitKey, tuple[np.ndarray, np.ndarray, float]],
    focal_px: float,
) -> list[dict[str, Any]]:
    """The rows with their fruit's offset taken out of the bearing errors: what is left is
    each view's own error."""
    out = []
    for r in det:
        found = offsets.get(fruit_key(r))
        if found is None:
            out.append(r)
            continue
        R = np.asarray(r["camera_rotation"], dtype=float)
        k = focal_px / r["distance_m"]
        out.append(
            {
                **r,
                "err_u_px": r["err_u_px"] - k * float(R[:, 1] @ found[0]),
                "err_v_px": r["err_v_px"] - k * float(R[:, 2] @ found[0]),
            }
        )
    return out


def _offset_bound(
    offsets: dict[FruitKey, tuple[np.ndarray, np.ndarray, float]],
) -> tuple[float, float]:
    """(β_h, β_v): the fruit's own offset bounded as N(0, diag(β_h, β_h, β_v)² r²), its shape
    from the offsets' spread (mean of b² - diag C over fruits, horizontal and vertical) and
    its size such that 97.1% of the fruits' offsets (χ²₃(9): an honest 3σ ellipsoid's share)
    lie within 3σ of it, each with its own estimation covariance C: the offsets are
    heavy-tailed, so their variance alone would bound the typical fruit and miss the rest."""
    if not offsets:
        return (0.0, 0.0)
    rel = [(b / r, C / r**2) for b, C, r in offsets.values()]
    h = max(float(np.mean([0.5 * (b[0] ** 2 - C[0, 0] + b[1] ** 2 - C[1, 1]) for b, C in rel])), 1e-8)
    v = max(float(np.mean([b[2] ** 2 - C[2, 2] for b, C in rel])), 1e-8)
    shape = np.array([h, h, v])

    def inside(k: float) -> float:
        return float(np.mean([b @ np.linalg.solve(np.diag(k * shape) + C, b) <= 9.0 for b, C in rel]))

    lo, hi = 0.0, 1.0
    while inside(hi) < 0.971 and hi < 1e6:
        hi *= 2.0
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if inside(mid) < 0.971 else (lo, mid)
    return (math.sqrt(hi * h), math.sqrt(hi * v))


def seen_outlines(det: Sequence[dict[str, Any]]) -> dict[FruitKey, tuple[float, list[Outline]]]:
    """Per fruit (:func:`fruit_key`): its type's shape index and what its detections saw."""
    out: dict[FruitKey, tuple[float, list[Outline]]] = {}
    for r in det:
        key = fruit_key(r)
        _, outlines = out.setdefault(key, (float(r.get("fruit_shape_index", 1.0)), []))
        outlines.append(Outline(float(r.get("neighbour_share", 0.0))))
    return out


def _offset_terms(
    offsets: dict[FruitKey, tuple[np.ndarray, np.ndarray, float]],
    seen: dict[FruitKey, tuple[float, list[Outline]]],
    model: NoiseModel,
) -> tuple[float, ...]:
    """The coefficients (3,) of the fruit's own offset's variance on :data:`OFFSET_FEATURES`
    [share of the radius²]: each fruit's offset b ~ N(0, g(x) r² S + C), S the spread's
    (horizontal, vertical) shape of ``model.centre_bias_rel`` (mean 1), g(x) = c · x ≥ 0 over
    its features x; c fitted by maximum likelihood, then scaled so that 97.1% of the offsets
    lie within the 3σ ellipsoid (χ²₃(9), an honest 3σ ellipsoid's share), as the bound over
    all fruits is. () with fewer than 20 fruits."""
    from scipy.optimize import minimize

    h, v = model.centre_bias_rel
    mean = (2.0 * h * h + v * v) / 3.0
    fruits = [key for key in offsets if key in seen]
    if len(fruits) < 20 or mean <= 0.0:
        return ()
    shape = np.array([h * h, h * h, v * v]) / mean
    X = np.array([NoiseModel.offset_features(*seen[key]) for key in fruits])
    rel = [(offsets[key][0] / offsets[key][2], offsets[key][1] / offsets[key][2] ** 2) for key in fruits]

    def distances(c: np.ndarray) -> np.ndarray:
        return np.array(
            [b @ np.linalg.solve(np.diag(g * shape) + C, b) for g, (b, C) in zip(X @ c, rel, strict=True)]
        )

    def nll(p: np.ndarray) -> float:
        c = np.exp(p)
        dets = [np.linalg.slogdet(np.diag(g * shape) + C)[1] for g, (_, C) in zip(X @ c, rel, strict=True)]
        return float(0.5 * (np.sum(dets) + np.sum(distances(c))))

    start = np.full(len(OFFSET_FEATURES), math.log(mean / len(OFFSET_FEATURES)))
    best = minimize(nll, start, method="Nelder-Mead", options={"maxiter": 4000, "xatol": 1e-4, "fatol": 1e-6})
    c = np.exp(best.x)
    lo, hi = 0.0, 1.0
    while np.mean(distances(hi * c) <= 9.0) < 0.971 and hi < 1e6:
        hi *= 2.0
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if np.mean(distances(mid * c) <= 9.0) < 0.971 else (lo, mid)
    return tuple(float(x) for x in hi * c)


def _refusal_scale(rows: Sequence[dict[str, Any]], model: NoiseModel) -> tuple[float, int]:
    """b ≥ 0 and the number of fruits it was fitted to: per fruit (the rows of one scenario
    and scene, refused views included), the share ρ of its views the detector refused and
    the sum S of its detections' squared normalised errors (n components, the fruit's own
    offset left in: an episode's few views share it); S ~ s² χ²ₙ with s² = exp(a + b ρ),
    fitted by maximum likelihood. exp(b ρ) is what a fruit refused that often errs beyond
    one never refused."""
    from scipy.optimize import minimize

    groups: dict[FruitKey, list[dict[str, Any]]] = {}
    for r in rows:
        if "scenario" in r and "scene_seed" in r:
            groups.setdefault(fruit_key(r), []).append(r)
    share, total, count = [], [], []
    for views in groups.values():
        det = [r for r in views if r.get("detected")]
        if len(det) < 2:
            continue
        z = _components(det, model)
        share.append(1.0 - len(det) / len(views))
        total.append(float(np.sum(np.square(z))))
        count.append(z.size)
    if len(share) < 10 or np.ptp(share) == 0.0:
        return 0.0, len(share)
    rho, S, n = np.array(share), np.array(total), np.array(count)

    def nll(p: np.ndarray) -> float:
        log_s2 = p[0] + p[1] * rho
        return float(np.sum(0.5 * n * log_s2 + 0.5 * S * np.exp(-log_s2)))

    best = minimize(nll, np.zeros(2), method="Nelder-Mead")
    return max(float(best.x[1]), 0.0), len(share)


def _components(det: Sequence[dict[str, Any]], model: NoiseModel) -> np.ndarray:
    """The normalised errors (u, v, α) of these detections under ``model``, flattened."""
    out = []
    for r in det:
        sc, sr = row_sigmas(model, r)
        e = r["err_alpha_px"] - model.radius_bias(r["radius_px"])
        out += [r["err_u_px"] / sc, r["err_v_px"] / sc, e / sr]
    return np.array(out)


def _view_correlations(
    det: Sequence[dict[str, Any]], model: NoiseModel
) -> tuple[ViewCorrelation, ViewCorrelation]:
    """ρ(θ) of the centre's and the apparent radius' per-view errors (the fruit's own offset
    taken out), from every pair of views of one fruit (rows of one :func:`fruit_key` with
    their camera position and the truth): per pair, the cosine of the angle between the
    directions from the fruit to the two cameras and the products of their normalised errors
    (the centre's as the world-frame lateral error vectors' dot product over 2)."""
    groups: dict[FruitKey, list[tuple[np.ndarray, np.ndarray, float]]] = {}
    for r in det:
        if "camera_position_m" not in r or "camera_rotation" not in r:
            continue
        d = np.asarray(r["camera_position_m"], dtype=float) - np.asarray(r["truth_m"], dtype=float)
        R = np.asarray(r["camera_rotation"], dtype=float)
        sc, sr = row_sigmas(model, r)
        lateral = (R[:, 1] * r["err_u_px"] + R[:, 2] * r["err_v_px"]) / sc
        z_radius = (r["err_alpha_px"] - model.radius_bias(r["radius_px"])) / sr
        groups.setdefault(fruit_key(r), []).append((d / np.linalg.norm(d), lateral, z_radius))
    cos, centre, radius = [], [], []
    for views in groups.values():
        for i, (di, ci, ri) in enumerate(views):
            for dj, cj, rj in views[i + 1 :]:
                cos.append(float(di @ dj))
                centre.append(float(ci @ cj) / 2.0)
                radius.append(ri * rj)
    return fit_view_correlation(cos, centre), fit_view_correlation(cos, radius)


def noise_report(rows: Sequence[dict[str, Any]], model: NoiseModel) -> dict[str, Any]:
    """How well ``model`` describes the detected ``rows``: the normalised errors z = e / σ
    (bias removed) of the centre and of the apparent radius, their rms (1 if the variance is
    right) and their share beyond 2σ and 3σ (Gaussian: 4.55% and 0.27%); and the raw errors'
    rms [px]."""
    out: dict[str, Any] = {"detections": len(rows)}
    zc, zr, ec, er = [], [], [], []
    for r in rows:
        sc, sr = row_sigmas(model, r)
        zc += [r["err_u_px"] / sc, r["err_v_px"] / sc]
        ec += [r["err_u_px"], r["err_v_px"]]
        e = r["err_alpha_px"] - model.radius_bias(r["radius_px"])
        zr.append(e / sr)
        er.append(e)
    for name, z, e in (("centre", np.array(zc), np.array(ec)), ("radius", np.array(zr), np.array(er))):
        out[name] = {
            "error_rms_px": float(np.sqrt(np.mean(e**2))),
            "z_rms": float(np.sqrt(np.mean(z**2))),
            "beyond_2sigma_pct": float(100.0 * np.mean(np.abs(z) > 2.0)),
            "beyond_3sigma_pct": float(100.0 * np.mean(np.abs(z) > 3.0)),
        }
    return out
