"""The claim's tail scale κ² (``bve-mj calibrate``): how much the covariance an episode claims
must grow for its 99.9% ellipsoid to hold 99.9% of the errors of episode-like estimates made
from the calibration views."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from bve_mj.estimation.noise import INNOVATION_PRIOR_DOF, NoiseModel, Outline

__all__ = ["TAIL_DRAWS", "TAIL_PROBABILITY", "tail_scale"]

TAIL_PROBABILITY = 0.999

"""The share of episode-like estimates whose error the claimed covariance's ellipsoid at this
probability must hold (the scenario suite's silent failures are judged at it)."""

TAIL_DRAWS = 200

"""Episode-like draws of views per calibration fruit (:func:`_tail_scale`)."""


def tail_scale(
    kept: Sequence[dict[str, Any]],
    refused: Sequence[dict[str, Any]],
    model: NoiseModel,
    focal_px: float,
    sigmas_px: Callable[[dict[str, Any]], tuple[float, float]],
) -> float:
    """κ² ≥ 1: how much the covariance an episode claims must grow for its χ²₃ ellipsoid at
    :data:`TAIL_PROBABILITY` to hold that share of the errors of episode-like estimates.

    An episode's estimate is not one view: it fuses a few, and claims the filter's covariance
    (scaled by its innovations), the fruit's own offset from what was seen, and the refusal
    scale. So the tail is measured on what an episode would claim from the calibration
    views: per fruit, :data:`TAIL_DRAWS` draws of 3 to 6 of its views (seeded), each fused
    by the linearised filter at the truth (bearing and apparent size, centre and radius in
    the state, each view's noise from ``model``, a view near the ones drawn before it
    counted as the share it adds), its error against the claim. The errors of single views
    are heavy-tailed (2% beyond 3σ, calibration seed 1), and a per-view κ² (2.6 there) made
    every claim three times too wide; fused and claimed as the loop claims, the 99.9%
    quantile is 1.8 times χ²₃'s there. 1 with fewer than 20 fruits of 4 views.

    ``sigmas_px(row)``: the per-view σ of the centre's image coordinates and of the apparent
    radius the model gives that row [px]."""
    from bve_mj.estimation.metrics import chi2_quantile
    from bve_mj.estimation.models import BearingSizeModel
    from bve_mj.estimation.view_correlation import new_view_share

    views_of: dict[tuple[Any, Any], list[dict[str, Any]]] = {}
    for r in kept:
        if "camera_rotation" in r and "camera_position_m" in r and "truth_m" in r:
            views_of.setdefault((r.get("scenario"), r.get("scene_seed")), []).append(r)
    shares: dict[tuple[Any, Any], list[bool]] = {}
    for r in [*kept, *refused]:
        shares.setdefault((r.get("scenario"), r.get("scene_seed")), []).append(not r.get("detected"))
    fruits = {key: rows for key, rows in views_of.items() if len(rows) >= 4}
    if len(fruits) < 20:
        return 1.0
    rng = np.random.default_rng(0)
    nees = []
    for key, rows in fruits.items():
        truth, radius = np.asarray(rows[0]["truth_m"], dtype=float), float(rows[0]["true_radius_m"])
        x = np.r_[truth, radius]
        prior_info = np.diag([1.0 / 0.05**2] * 3 + [1.0 / (0.087 * radius) ** 2])  # a wide prior
        refusal = math.exp(model.refusal_scale * float(np.mean(shares[key])))
        shape_index = float(rows[0].get("fruit_shape_index", 1.0))
        for _ in range(TAIL_DRAWS):
            drawn = [
                rows[i]
                for i in rng.choice(len(rows), size=min(int(rng.integers(3, 7)), len(rows)), replace=False)
            ]
            info, grad = prior_info.copy(), np.zeros(4)
            taken: list[np.ndarray] = []
            terms: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
            for r in drawn:
                p = np.asarray(r["camera_position_m"], dtype=float)
                sc, sr = sigmas_px(r)
                e = np.array(
                    [r["err_u_px"], r["err_v_px"], r["err_alpha_px"] - model.radius_bias(r["radius_px"])]
                )
                cov = np.diag([sc**2, sc**2, sr**2]) / focal_px**2
                direction = (p - truth) / np.linalg.norm(p - truth)
                if taken:
                    cs = new_view_share(model.centre_correlation, np.array(taken), direction)[0]
                    rs = new_view_share(model.radius_correlation, np.array(taken), direction)[0]
                    cov = cov / np.outer(np.sqrt([cs, cs, rs]), np.sqrt([cs, cs, rs]))
                taken.append(direction)
                H = BearingSizeModel(p, np.asarray(r["camera_rotation"], dtype=float), cov).jacobian(x)
                W = np.linalg.inv(cov)
                info += H.T @ W @ H
                grad += H.T @ W @ (e / focal_px)
                terms.append((H, W, e / focal_px))
            P = np.linalg.inv(info)
            dx = P @ grad
            cost = float(dx @ prior_info @ dx) + sum(
                float((z - H @ dx) @ W @ (z - H @ dx)) for H, W, z in terms
            )
            s2 = (INNOVATION_PRIOR_DOF + cost) / (INNOVATION_PRIOR_DOF + 3 * len(drawn))
            outlines = [Outline(float(r["arc_deg"]), float(r.get("neighbour_share", 0.0))) for r in drawn]
            claim = (P[:3, :3] * s2 + model.centre_offset_cov(radius, shape_index, outlines)) * refusal
            nees.append(float(dx[:3] @ np.linalg.solve(claim, dx[:3])))
    ratio = float(np.quantile(nees, TAIL_PROBABILITY)) / float(chi2_quantile(TAIL_PROBABILITY, 3))
    return max(1.0, ratio)
