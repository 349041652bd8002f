"""What a detector errs on fruit it sees coloured in part, beyond the model over every fruit.

A detector asked for fruit short of red (``detector.ripe_class`` ``turning``, ``pink`` or
``light_red``: a market that harvests early) fits the coloured part of a fruit that may be
coloured only in part: a turning fruit shows 10-30% of its skin coloured, from the blossom
end up, and the fit's circle follows that cap's edge where the silhouette is green. Against
the truth (calibration seed 11, ``bve-mj calibrate --only turning``: 188 views of 8 fruits)
its apparent radius lies 0.66 px below the model's bias, its views err 4.9 (centre) and 3.2
(radius) times the model's variance, and the centre it fits is off the fruit's true centre
by the same amount from every view, several times a red fruit's own offset. So the model
holds, for such a detector, the views' bias and variance scales
(``NoiseModel.partial_colour_view``, applied by :meth:`~bve_mj.estimation.noise.NoiseModel.
for_partial_colour`: :func:`fit_partial_colour_view`) and the variance the claim adds for the
offset, a share ``NoiseModel.partial_colour_offset`` of the radius²
(:func:`fit_partial_colour_offset`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np

from bve_mj.config.detector import RED_CLASSES
from bve_mj.estimation.noise import NoiseModel, load_noise_model
from bve_mj.estimation.noise_fit import fruit_offsets, seen_outlines, without_offsets
from bve_mj.estimation.noise_tail import row_sigmas

__all__ = [
    "MIN_FRUITS",
    "MIN_VIEWS",
    "detector_noise_model",
    "fit_partial_colour",
    "fit_partial_colour_offset",
    "fit_partial_colour_view",
    "partial_colour_cov",
]

if TYPE_CHECKING:
    from bve_mj.config import Settings

MIN_VIEWS = 30
"""Detections of such fruit :func:`fit_partial_colour_view` needs; with fewer it fits none."""

MIN_FRUITS = 5
"""Such fruits (6 views or more) :func:`fit_partial_colour_offset` needs; with fewer it fits none."""


def detector_noise_model(settings: Settings) -> NoiseModel:
    """The calibrated noise of ``settings``' detector, as the filter and the planner use it:
    ``measurement.noise_model`` loaded and checked against the camera (a
    :class:`~bve_mj.errors.ConfigError` naming the file otherwise), with its views' terms
    applied (:meth:`~bve_mj.estimation.noise.NoiseModel.for_partial_colour`) for a detector
    of a class short of red."""
    noise = load_noise_model(settings.measurement.noise_model)
    noise.check_camera(settings.camera, settings.measurement.noise_model)
    return noise.for_partial_colour() if settings.detector.partial_colour else noise


def partial_colour_cov(model: NoiseModel, radius_m: float) -> np.ndarray:
    """The covariance [m²] (3, 3) the claim adds for a fruit of ``radius_m`` a detector of a
    class short of red measures: ``model.partial_colour_offset`` · r², shaped (horizontal,
    vertical) as the fruit's own offset's bound (``model.centre_bias_rel``)."""
    h, v = model.centre_bias_rel
    mean = (2.0 * h * h + v * v) / 3.0
    if mean <= 0.0 or model.partial_colour_offset <= 0.0:
        return np.zeros((3, 3))
    return np.diag([h * h, h * h, v * v]) * (model.partial_colour_offset / mean) * radius_m**2


def fit_partial_colour_view(
    kept: Sequence[dict[str, Any]], model: NoiseModel, focal_px: float
) -> tuple[tuple[float, float, float], int]:
    """((δ, k_c, k_r), n): what the ``n`` views of a detector of a class short of red (rows
    whose ``ripe_class`` is not red) err beyond ``model``: δ [px] the mean of their apparent
    radius' error after the model's bias (a bias, removed), and k_c, k_r the mean squared
    error of their centre (each fruit's own offset taken out first) and of their apparent
    radius (δ taken out) over the model's variance, at least 1: such a view never claims
    less noise than the model over every fruit says. ((0, 1, 1), n) with fewer than
    :data:`MIN_VIEWS`."""

    rows = [r for r in kept if r.get("ripe_class") not in RED_CLASSES]
    if len(rows) < MIN_VIEWS:
        return (0.0, 1.0, 1.0), len(rows)
    own = without_offsets(rows, fruit_offsets(rows, model, focal_px), focal_px)
    radius = np.array([r["err_alpha_px"] - model.radius_bias(r["radius_px"]) for r in own])
    sigmas = np.array([row_sigmas(model, r) for r in own])
    centre = np.array([0.5 * (r["err_u_px"] ** 2 + r["err_v_px"] ** 2) for r in own]) / sigmas[:, 0] ** 2
    delta = float(np.mean(radius))
    k_r = float(np.mean(((radius - delta) / sigmas[:, 1]) ** 2))
    return (delta, max(1.0, float(np.mean(centre))), max(1.0, k_r)), len(rows)


def fit_partial_colour_offset(
    kept: Sequence[dict[str, Any]], model: NoiseModel, focal_px: float
) -> tuple[float, int]:
    """(s, n): the share s of the radius² that the own offset of the ``n`` calibration fruits
    measured by a detector of a class short of red (rows whose ``ripe_class`` is not red)
    adds to ``model``'s offset for them. Each such fruit's offset b (the weighted least-squares
    offset its views share, with its covariance C) is taken as N(0, (g + s) r² S + C), g the
    model's own share for it (its shape and neighbours) and S the bound's shape; s is fitted
    by maximum likelihood and then raised, if need be, until 97.1% of the offsets lie within
    the 3σ ellipsoid (χ²₃(9): an honest 3σ ellipsoid's share), as the model's own offset is
    sized. (0, n) with fewer than :data:`MIN_FRUITS` such fruits."""
    from scipy.optimize import minimize_scalar

    partial = [r for r in kept if r.get("ripe_class") not in RED_CLASSES]
    offsets = fruit_offsets(partial, model, focal_px)
    seen = seen_outlines(partial)
    h, v = model.centre_bias_rel
    mean = (2.0 * h * h + v * v) / 3.0
    if len(offsets) < MIN_FRUITS or mean <= 0.0:
        return 0.0, len(offsets)
    shape = np.array([h * h, h * h, v * v]) / mean
    fruits = []
    for key, (b, C, r) in offsets.items():
        base = model.centre_offset_cov(r, *seen[key])  # the model's own, shaped as the bound
        g = float(np.trace(base) / r**2 / np.sum(shape)) if r > 0.0 else 0.0
        fruits.append((b / r, C / r**2, g))

    def distances(s: float) -> np.ndarray:
        return np.array([b @ np.linalg.solve(np.diag((g + s) * shape) + C, b) for b, C, g in fruits])

    def nll(log_s: float) -> float:
        s = math.exp(log_s)
        dets = [np.linalg.slogdet(np.diag((g + s) * shape) + C)[1] for _, C, g in fruits]
        return float(0.5 * (np.sum(dets) + np.sum(distances(s))))

    best = minimize_scalar(nll, bounds=(math.log(1e-9), math.log(1e-2)), method="bounded")
    s = math.exp(float(best.x))
    lo, hi = s, s
    while np.mean(distances(hi) <= 9.0) < 0.971 and hi < 1.0:
        hi *= 2.0
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if np.mean(distances(mid) <= 9.0) < 0.971 else (lo, mid)
    return float(hi), len(fruits)


def fit_partial_colour(
    kept: Sequence[dict[str, Any]], model: NoiseModel, focal_px: float
) -> tuple[NoiseModel, int, int]:
    """(model', views, fruits): ``model`` with both terms fitted from the rows of a detector of
    a class short of red (``views`` of them, ``fruits`` with 6 views or more): the views' bias
    and variance scales (:func:`fit_partial_colour_view`), then, under them, the offset
    (:func:`fit_partial_colour_offset`). With too few rows a term is none ((0, 1, 1) and 0),
    never the one ``model`` held: a model is fitted from its own rows."""
    view, views = fit_partial_colour_view(kept, model, focal_px)
    viewed = replace(model, partial_colour_view=view)
    share, fruits = fit_partial_colour_offset(kept, viewed.for_partial_colour(), focal_px)
    return replace(viewed, partial_colour_offset=share), views, fruits
