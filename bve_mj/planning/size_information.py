"""The information the filter's own bearing/size measurement adds: the planner's model for the
radius-in-state filter (:class:`SizeInformation`, :func:`size_information`).

Hᵀ W H of the bearing and apparent-size (or size-only) measurement of a camera at c looking at
the estimate, with the noise the calibrated detector model expects of a whole fruit at that
distance, and its analytic derivative in c; views near those already fused count as the share
of a fresh view they add. :mod:`bve_mj.planning.information` holds the paper's models and the
failed-view discount beside it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

import bve_mj.linalg as la
from bve_mj.config import Settings
from bve_mj.estimation.view_correlation import TakenViews, ViewCorrelation
from bve_mj.geometry import camera_frame, frame_rotation, frame_rotation_derivative

__all__ = ["SizeInformation", "size_information"]

Derivative = Callable[[], np.ndarray]  # ∂Λn/∂c (n, n, 3), computed when called
_RowDerivatives = Callable[[], tuple[np.ndarray, np.ndarray]]  # ∂H/∂c (m, n, 3), ∂W/∂c (m, 3)


@dataclass(frozen=True)
class SizeInformation:
    """Λn = Hᵀ W H of the bearing/size measurement (or, ``bearing = False``, the apparent size
    alone) of a camera at c looking at the estimate, over a state (4,) or (7,) (see
    :mod:`bve_mj.estimation.models`), linearised at x̂.

    Looking at k̂ the camera sees it on its axis at ρ = ‖k̂ - c‖ with apparent radius
    α = asin(r̂/ρ), T = tan α; g = 1 + ε̂ with the focal bias ε̂ (0 without biases). Rows of H:
    bearing u: (y_C/(ρg), 0, 1/g, 0, -δ̂y/g²), v: (z_C/(ρg), 0, 0, 1/g, -δ̂z/g²); size:
    (-A₁ T x_C/ρ, A₁/(ρ cos α), 0, 0, A₂) with A₁ = g(1 + T²)/(g² + T²), A₂ = -T/(g² + T²)
    (the bias columns only in a state of 7). The noise the calibrated model expects of a
    whole fruit of apparent radius f·T [px], as variances [rad²] of the form a + b·T²:
    ``bearing_var`` and ``size_var``. Every factor is a function of ρ (and R_C^W of c): the
    derivative is analytic.

    ``taken``: unit directions (k, 3) from the estimate to the views fused so far; a view
    from a nearby direction shares their errors and is expected to add only its share Δ(e)
    of a fresh view's information (:func:`~bve_mj.estimation.view_correlation.
    new_view_share`, per component with ``correlation`` = (centre, apparent radius)), the
    way the filter will fuse it: the BVE then prefers a view that adds evidence of its own
    to a repeat of the best one.
    """

    bearing_var: tuple[float, float]
    size_var: tuple[float, float]
    bearing: bool = True
    taken: np.ndarray | None = None
    correlation: tuple[ViewCorrelation, ViewCorrelation] = (ViewCorrelation(), ViewCorrelation())

    def __post_init__(self) -> None:
        views = None
        if self.taken is not None and len(self.taken):
            views = tuple(TakenViews.of(corr, self.taken) for corr in self.correlation)
        object.__setattr__(self, "_taken_views", views)

    def _rows(self, c: np.ndarray, x_hat: np.ndarray) -> tuple[np.ndarray, np.ndarray, _RowDerivatives]:
        """H (m, n), W (m,), and a function that gives their derivatives in c, (m, n, 3) and
        (m, 3), from the same intermediates (H and W the same bits whether it is called or not)."""
        n = len(x_hat)
        k, r = x_hat[:3], float(x_hat[3])
        dy, dz, eps = (x_hat[4], x_hat[5], x_hat[6]) if n == 7 else (0.0, 0.0, 0.0)
        g = 1.0 + eps
        frame = camera_frame(c, k)
        R = frame_rotation(frame)
        x = R[:, 0]
        rho = la.norm(k - np.asarray(c, dtype=float))
        s = min(r / rho, 0.99)
        cos_a = math.sqrt(1.0 - s * s)
        T = s / cos_a
        sec = 1.0 / cos_a
        den = g * g + T * T
        A1 = g * (1.0 + T * T) / den
        A2 = -T / den
        # scalar factors of ρ and their derivatives d/dρ (dα/dρ = -T/ρ, dT/dρ = -(1 + T²) T/ρ)
        dT = -(1.0 + T * T) * T / rho
        dA1 = 2.0 * g * T * (g * g - 1.0) / den**2 * dT
        dA2 = -(g * g - T * T) / den**2 * dT
        s_a, ds_a = -A1 * T / rho, -(dA1 * T + A1 * dT) / rho + A1 * T / rho**2
        s_r = A1 * sec / rho
        ds_r = (dA1 * sec + A1 * sec * T * (-T / rho)) / rho - A1 * sec / rho**2
        va, vb = self.size_var
        w_a, dw_a = 1.0 / (va + vb * T * T), -(2.0 * vb * T * dT) / (va + vb * T * T) ** 2
        rows, drows_rho, w, dw_rho = [], [], [], []
        size = np.zeros(n)
        size[:3], size[3] = s_a * x, s_r
        dsize = np.zeros(n)
        dsize[:3], dsize[3] = ds_a * x, ds_r
        if n == 7:
            size[6], dsize[6] = A2, dA2
        if self.bearing:
            ba, bb = self.bearing_var
            w_b, dw_b = 1.0 / (ba + bb * T * T), -(2.0 * bb * T * dT) / (ba + bb * T * T) ** 2
            for axis, delta, col in ((1, dy, 4), (2, dz, 5)):
                h, dh = np.zeros(n), np.zeros(n)
                h[:3], dh[:3] = R[:, axis] / (rho * g), -R[:, axis] / (rho * rho * g)
                if n == 7:
                    h[col], h[6] = 1.0 / g, -delta / g**2
                rows.append(h)
                drows_rho.append(dh)
                w.append(w_b)
                dw_rho.append(dw_b)
        rows.append(size)
        drows_rho.append(dsize)
        w.append(w_a)
        dw_rho.append(dw_a)
        H, W0 = np.array(rows), np.array(w)
        shares = self._view_shares(-x, rho, len(w))
        W = W0 if shares is None else W0 * shares[0]

        def derivative() -> tuple[np.ndarray, np.ndarray]:
            dR = frame_rotation_derivative(frame)
            drho = -x  # dρ/dc
            dH = np.einsum("mi,j->mij", np.array(drows_rho), drho)
            # R_C^W's columns in the centre's entries: d(coef · axis)/dc = coef · d(axis)/dc
            if self.bearing:
                dH[0, :3, :] += dR[:, 1, :] / (rho * g)
                dH[1, :3, :] += dR[:, 2, :] / (rho * g)
            dH[-1, :3, :] += s_a * dR[:, 0, :]
            dW = np.outer(np.array(dw_rho), drho)
            if shares is not None:
                f, df = shares
                dW = dW * f[:, None] + W0[:, None] * df
            return dH, dW

        return H, W, derivative

    def _view_shares(self, e: np.ndarray, rho: float, m: int) -> tuple[np.ndarray, np.ndarray] | None:
        """The share Δ of a fresh view that each of the m rows (the bearing rows, then the
        size row) of a view from direction ``e`` at distance ``rho`` adds beside ``taken``,
        (m,), and its derivative in c, (m, 3); None when every view counts in full."""
        views: tuple[TakenViews, TakenViews] | None = self._taken_views  # type: ignore[attr-defined]
        if views is None:
            return None
        P = (np.eye(3) - np.outer(e, e)) / rho  # ∂e/∂c
        (fc, dfc), (fr, dfr) = (v.share(e) for v in views)
        f = np.array([fc] * (m - 1) + [fr])
        df = np.array([P @ dfc] * (m - 1) + [P @ dfr])
        return f, df

    def information(self, c: np.ndarray, x_hat: np.ndarray) -> np.ndarray:
        H, W, _ = self._rows(c, x_hat)
        return (H.T * W) @ H

    def information_derivative(self, c: np.ndarray, x_hat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        L, d_information = self.information_lazy(c, x_hat)
        return L, d_information()

    def information_lazy(self, c: np.ndarray, x_hat: np.ndarray) -> tuple[np.ndarray, Derivative]:
        """:meth:`information_derivative` with ∂Λn/∂c computed when asked (same bits)."""
        H, W, derivative = self._rows(c, x_hat)
        HW = H.T * W  # (n, m)

        def d_information() -> np.ndarray:
            dH, dW = derivative()
            T = np.einsum("im,mjk->ijk", HW, dH)  # Hᵀ W dH
            return T + T.transpose(1, 0, 2) + np.einsum("mi,mk,mj->ijk", H, dW, H)

        return HW @ H, d_information


def size_information(settings: Settings) -> SizeInformation:
    """The planner's model for the radius-in-state filter under ``settings``: the calibrated
    noise (``measurement.noise_model``) of a whole fruit of the prior's shape index, and
    the encoders' white bearing noise."""
    from bve_mj.estimation.noise import load_noise_model

    noise = load_noise_model(settings.measurement.noise_model)
    f = settings.camera.focal_px
    k = settings.fruit.shape_index
    # a whole fruit, no neighbour: σ² [px²] = a + b·r_px² with r_px = f·T; in rad², a/f² + b·T²
    # (a: the floor and the typical fit; b: the terms that grow with the apparent radius)
    constant = noise.features(0.0, 360.0, noise.typical_fit_px, k)
    per_r2 = noise.features(1.0, 360.0, 0.0, k) - noise.features(0.0, 360.0, 0.0, k)
    c0, c1 = float(np.dot(noise.centre_var_px2, constant)), float(np.dot(noise.centre_var_px2, per_r2))
    r0, r1 = float(np.dot(noise.radius_var_px2, constant)), float(np.dot(noise.radius_var_px2, per_r2))
    enc = (2.5 * settings.sensor.encoder_noise_rad) ** 2
    return SizeInformation(
        (c0 / f**2 + enc, float(c1)),
        (r0 / f**2, float(r1)),
        settings.measurement.kind != "range",
        correlation=(noise.centre_correlation, noise.radius_correlation),
    )
