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
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

import bve_mj.linalg as la
from bve_mj.config import Settings
from bve_mj.estimation.view_correlation import TakenViews, ViewCorrelation
from bve_mj.geometry import VERTICAL_EPS, camera_frame, frame_rotation, frame_rotation_derivative

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
    whole fruit of apparent radius f·T [px], as variances [rad²] of the form a + b·T² + c·T⁴
    (c the close view's term; a pair (a, b) holds c = 0): ``bearing_var`` and ``size_var``.
    Every factor is a function of ρ (and R_C^W of c): the derivative is analytic.

    ``taken``: unit directions (k, 3) from the estimate to the views fused so far; a view
    from a nearby direction shares their errors and is expected to add only its share Δ(e)
    of a fresh view's information (:func:`~bve_mj.estimation.view_correlation.
    new_view_share`, per component with ``correlation`` = (centre, apparent radius)), the
    way the filter will fuse it: the BVE then prefers a view that adds evidence of its own
    to a repeat of the best one. ``taken_at``: the camera positions of those views [m] (k, 3),
    for the part of the error views from nearby places share (a camera that holds where it
    is expects almost nothing of the view it repeats).
    """

    bearing_var: tuple[float, ...]
    size_var: tuple[float, ...]
    bearing: bool = True
    taken: np.ndarray | None = None
    correlation: tuple[ViewCorrelation, ViewCorrelation] = (ViewCorrelation(), ViewCorrelation())
    taken_at: np.ndarray | None = None

    def __post_init__(self) -> None:
        views = None
        if self.taken is not None and len(self.taken):
            views = tuple(TakenViews.of(corr, self.taken, self.taken_at) for corr in self.correlation)
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
        clipped = r / rho > 0.99  # the camera at the skin: the apparent size held, T constant
        s = 0.99 if clipped else r / rho
        cos_a = math.sqrt(1.0 - s * s)
        T = s / cos_a
        sec = 1.0 / cos_a
        den = g * g + T * T
        A1 = g * (1.0 + T * T) / den
        A2 = -T / den
        # scalar factors of ρ and their derivatives d/dρ (dα/dρ = -T/ρ, dT/dρ = -(1 + T²) T/ρ,
        # d sec/dρ = sec T dα/dρ)
        dT = 0.0 if clipped else -(1.0 + T * T) * T / rho
        dsec = 0.0 if clipped else sec * T * (-T / rho)
        dA1 = 2.0 * g * T * (g * g - 1.0) / den**2 * dT
        dA2 = -(g * g - T * T) / den**2 * dT
        s_a, ds_a = -A1 * T / rho, -(dA1 * T + A1 * dT) / rho + A1 * T / rho**2
        s_r = A1 * sec / rho
        ds_r = (dA1 * sec + A1 * dsec) / rho - A1 * sec / rho**2
        w_a, dw_a = _weight(self.size_var, T, dT)
        rows, drows_rho, w, dw_rho = [], [], [], []
        size = np.zeros(n)
        size[:3], size[3] = s_a * x, s_r
        dsize = np.zeros(n)
        dsize[:3], dsize[3] = ds_a * x, ds_r
        if n == 7:
            size[6], dsize[6] = A2, dA2
        if self.bearing:
            w_b, dw_b = _weight(self.bearing_var, T, dT)
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
        shares = self._view_shares(-x, rho, len(w), np.asarray(c, dtype=float))
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

    def _view_shares(
        self, e: np.ndarray, rho: float, m: int, c: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """The share Δ of a fresh view that each of the m rows (the bearing rows, then the
        size row) of a view from direction ``e`` at distance ``rho`` adds beside ``taken``,
        (m,), and its derivative in c, (m, 3); None when every view counts in full."""
        views: tuple[TakenViews, TakenViews] | None = self._taken_views  # type: ignore[attr-defined]
        if views is None:
            return None
        P = (np.eye(3) - np.outer(e, e)) / rho  # ∂e/∂c
        (fc, dfc, dcc), (fr, dfr, dcr) = (v.share_at(e, c) for v in views)
        gc, gr = P @ dfc() + dcc(), P @ dfr() + dcr()
        f = np.array([fc] * (m - 1) + [fr])
        df = np.array([gc] * (m - 1) + [gr])
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

    def dispersion_lazy(
        self,
        c: np.ndarray,
        x_hat: np.ndarray,
        prior_precision: Sequence[Sequence[float]],
        odds: tuple[float, Callable[[], np.ndarray]] | None = None,
    ) -> tuple[float, Callable[[], np.ndarray]]:
        """The dispersion loss ln det [(p·Λn(c) + Λo)⁻¹]_cc of a state of 4 (centre, radius)
        and a function that computes its gradient in c (3,): ``prior_precision`` Λo as rows,
        ``odds`` p(c) and its gradient function (:meth:`FailedViewDiscount.odds_lazy`; None:
        p = 1). The same function as :class:`~bve_mj.planning.losses.DispersionLoss` over
        :meth:`information_lazy`, in one pass of floats (value 111 → 8 µs, with the gradient
        205 → 20 µs: the objective was most of a plan's time): Λn = a (I - x xᵀ) ⊕ 0 + w v vᵀ
        with a = w_b f_c/ρ², the two bearing rows, and w = w_a f_r, v = (s_a x, s_r), the size
        row; M = p Λn + Λo by its Cholesky factor, the value -ln det M + ln M_rr (Schur
        complement), the gradient -tr(M⁻¹ ∂M) + ∂M_rr/M_rr from M⁻¹v and M⁻¹(x, 0).

        Raises:
            ValueError: for a state other than 4, a camera at the estimate, or an M that is
                not positive definite (the caller then takes the general path)."""
        if len(x_hat) != 4:
            raise ValueError(f"the fused dispersion is for a state of 4, got {len(x_hat)}")
        k0, k1, k2, r = np.asarray(x_hat, dtype=float).tolist()
        c0, c1, c2 = np.asarray(c, dtype=float).tolist()
        u0, u1, u2 = k0 - c0, k1 - c1, k2 - c2
        rho = math.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
        if rho == 0.0:
            raise ValueError("camera and target coincide: the viewing direction is undefined")
        x0, x1, x2 = u0 / rho, u1 / rho, u2 / rho
        clipped = r / rho > 0.99
        s = 0.99 if clipped else r / rho
        cos_a = math.sqrt(1.0 - s * s)
        T, sec = s / cos_a, 1.0 / cos_a
        s_a, s_r = -T / rho, sec / rho
        dT = 0.0 if clipped else -(1.0 + T * T) * T / rho
        w_a, dw_a = _weight(self.size_var, T, dT)
        w_b, dw_b = _weight(self.bearing_var, T, dT) if self.bearing else (0.0, 0.0)
        views: tuple[TakenViews, TakenViews] | None = self._taken_views  # type: ignore[attr-defined]
        fc, fr = 1.0, 1.0
        if views is not None:
            e = np.array([-x0, -x1, -x2])
            (fc, dfc, dcc), (fr, dfr, dcr) = (v.share_at(e, c) for v in views)
        p, dp = (1.0, None) if odds is None else odds
        a, wv = w_b * fc / (rho * rho), w_a * fr
        v0, v1, v2, v3 = s_a * x0, s_a * x1, s_a * x2, s_r
        pa, pw = p * a, p * wv
        (o00, o01, o02, o03), (_, o11, o12, o13), (_, _, o22, o23), (_, _, _, o33) = prior_precision
        # I - x xᵀ as y yᵀ + z zᵀ (the image axes, :func:`~bve_mj.geometry.camera_rotation`):
        # entry by entry it would leak ~1e-16 of the bearing information along the ray
        h = math.hypot(x0, x1)
        y0, y1 = (-x1 / h, x0 / h) if h > VERTICAL_EPS else (0.0, 1.0)
        z0, z1, z2 = -x2 * y1, x2 * y0, x0 * y1 - x1 * y0
        m00 = pa * (y0 * y0 + z0 * z0) + pw * v0 * v0 + o00
        m01 = pa * (y0 * y1 + z0 * z1) + pw * v0 * v1 + o01
        m02 = pa * (z0 * z2) + pw * v0 * v2 + o02
        m11 = pa * (y1 * y1 + z1 * z1) + pw * v1 * v1 + o11
        m12 = pa * (z1 * z2) + pw * v1 * v2 + o12
        m22 = pa * (z2 * z2) + pw * v2 * v2 + o22
        m03, m13, m23, m33 = pw * v0 * v3 + o03, pw * v1 * v3 + o13, pw * v2 * v3 + o23, pw * v3 * v3 + o33
        # A = L Lᵀ, A = M with the radius first (math.sqrt raises ValueError where M is not
        # positive definite): l00² = M_rr, and the centre block of L carries the Schur
        # complement S = M_cc - m_c m_cᵀ/M_rr, whose ln det is the value (= ln det M - ln M_rr
        # without taking the two large logarithms apart)
        l00 = math.sqrt(m33)
        l10, l20, l30 = m03 / l00, m13 / l00, m23 / l00
        l11 = math.sqrt(m00 - l10 * l10)
        l21, l31 = (m01 - l20 * l10) / l11, (m02 - l30 * l10) / l11
        l22 = math.sqrt(m11 - l20 * l20 - l21 * l21)
        l32 = (m12 - l30 * l20 - l31 * l21) / l22
        l33 = math.sqrt(m22 - l30 * l30 - l31 * l31 - l32 * l32)
        value = -2.0 * (math.log(l11) + math.log(l22) + math.log(l33))

        def gradient() -> np.ndarray:
            # L⁻¹ (lower triangular); M⁻¹y = L⁻ᵀ(L⁻¹y) in the radius-first order
            i00, i11, i22, i33 = 1.0 / l00, 1.0 / l11, 1.0 / l22, 1.0 / l33
            i10 = -l10 * i00 * i11
            i21 = -l21 * i11 * i22
            i20 = -(l20 * i00 + l21 * i10) * i22
            i32 = -l32 * i22 * i33
            i31 = -(l31 * i11 + l32 * i21) * i33
            i30 = -(l30 * i00 + l31 * i10 + l32 * i20) * i33

            def solve(y0: float, y1: float, y2: float, y3: float) -> tuple[float, float, float, float]:
                """M⁻¹ y for y = (centre, radius), in that order."""
                w0, w1 = i00 * y3, i10 * y3 + i11 * y0
                w2, w3 = i20 * y3 + i21 * y0 + i22 * y1, i30 * y3 + i31 * y0 + i32 * y1 + i33 * y2
                return (i11 * w1 + i21 * w2 + i31 * w3, i22 * w2 + i32 * w3, i33 * w3,
                        i00 * w0 + i10 * w1 + i20 * w2 + i30 * w3)  # fmt: skip

            mv0, mv1, mv2, mv3 = solve(v0, v1, v2, v3)  # M⁻¹ v
            nx0, nx1, nx2, _ = solve(x0, x1, x2, 0.0)  # M⁻¹ (x, 0)
            tr_n = i11 * i11 + i21 * i21 + i31 * i31 + i22 * i22 + i32 * i32 + i33 * i33  # tr S⁻¹
            v_mv = v0 * mv0 + v1 * mv1 + v2 * mv2 + v3 * mv3
            x_nx, x_mv = x0 * nx0 + x1 * nx1 + x2 * nx2, x0 * mv0 + x1 * mv1 + x2 * mv2
            tr_np = tr_n - x_nx  # tr(M⁻¹_cc (I - x xᵀ))
            # factors of ρ and their derivatives d/dρ (∂ρ/∂c = -x, ∂x/∂c_j = (x x_j - e_j)/ρ)
            ds_a = -dT / rho + T / (rho * rho)
            ds_r = (0.0 if clipped else sec * T * (-T / rho)) / rho - sec / (rho * rho)
            # tr(M⁻¹ ∂Λn_j) = ∂a_j tr_np - 2a (M⁻¹x)·∂x_j + ∂w_j v·M⁻¹v + 2w (M⁻¹v)·∂v_j, each
            # term α x_j + β (M⁻¹x)_j + γ (M⁻¹v)_j (+ the shares' own derivatives)
            da_x = -(dw_b * fc / (rho * rho) - 2.0 * w_b * fc / rho**3)
            dw_x = -dw_a * fr
            mv_dv_x = -ds_a * x_mv + s_a * x_mv / rho - mv3 * ds_r
            tr_x = da_x * tr_np - 2.0 * a * x_nx / rho + dw_x * v_mv + 2.0 * wv * mv_dv_x
            tr_nx, tr_mv = 2.0 * a / rho, -2.0 * wv * s_a / rho
            d33_x = p * (dw_x * s_r * s_r - 2.0 * wv * s_r * ds_r)  # ∂M_rr_j = d33_x x_j (+ shares)
            ax = -p * tr_x + d33_x / m33
            g = np.array([
                ax * x0 - p * (tr_nx * nx0 + tr_mv * mv0),
                ax * x1 - p * (tr_nx * nx1 + tr_mv * mv1),
                ax * x2 - p * (tr_nx * nx2 + tr_mv * mv2),
            ])  # fmt: skip
            if views is not None:
                P = (np.eye(3) - np.outer(e, e)) / rho  # ∂e/∂c
                g += (-p * w_b / (rho * rho) * tr_np) * (P @ dfc() + dcc())
                g += (-p * w_a * v_mv + p * w_a * s_r * s_r / m33) * (P @ dfr() + dcr())
            if dp is not None:  # ∂p: -tr(M⁻¹ Λn) + Λn_rr/M_rr
                g += (-(wv * v_mv + a * tr_np) + wv * v3 * v3 / m33) * dp()
            return g

        return value, gradient


def _weight(var: tuple[float, ...], T: float, dT: float) -> tuple[float, float]:
    """1/σ² of a noise σ² = a + b·T² (+ c·T⁴) [rad²] and its derivative d/dρ, given dT/dρ."""
    t2 = T * T
    v = var[0] + var[1] * t2 + (var[2] * t2 * t2 if len(var) > 2 else 0.0)
    dv = (2.0 * var[1] * T + (4.0 * var[2] * T * t2 if len(var) > 2 else 0.0)) * dT
    return 1.0 / v, -dv / (v * v)


def size_information(settings: Settings) -> SizeInformation:
    """The planner's model for the radius-in-state filter under ``settings``: the calibrated
    noise (``measurement.noise_model``, as the detector's views have it:
    :func:`~bve_mj.estimation.partial_colour.detector_noise_model`) of a whole fruit of the
    prior's shape index, and the encoders' white bearing noise."""
    from bve_mj.estimation.noise import FEATURES
    from bve_mj.estimation.partial_colour import detector_noise_model

    noise = detector_noise_model(settings)
    f = settings.camera.focal_px
    k = settings.fruit.shape_index
    # a whole fruit, no neighbour: σ² [px²] = a + b·r_px² + c·r_px⁴ with r_px = f·T; in rad²,
    # a/f² + b·T² + c·f²·T⁴ (a: the floor and the typical fit; b: the terms that grow with the
    # apparent radius; c: the close view's)
    constant = noise.features(0.0, 360.0, noise.typical_fit_px, k)
    grown = noise.features(1.0, 360.0, 0.0, k) - noise.features(0.0, 360.0, 0.0, k)
    per_r4 = np.zeros_like(grown)
    per_r4[FEATURES.index("near")] = grown[FEATURES.index("near")]  # (1/100)⁴ per r_px⁴
    per_r2 = grown - per_r4
    (c0, c1, c2), (r0, r1, r2) = (
        tuple(float(np.dot(coef, t)) for t in (constant, per_r2, per_r4))
        for coef in (noise.centre_var_px2, noise.radius_var_px2)
    )
    enc = (2.5 * settings.sensor.encoder_noise_rad) ** 2
    return SizeInformation(
        (c0 / f**2 + enc, c1, c2 * f**2),
        (r0 / f**2, r1, r2 * f**2),
        settings.measurement.kind != "range",
        correlation=(noise.centre_correlation, noise.radius_correlation),
    )
