"""Views from nearby directions share their errors: what a new view adds beside the taken ones.

The detector's error in a view is not white: it is what the fruit's silhouette (its shape,
its tilt, the neighbour or leaf edge beside it, the shading) looks like from that
direction, and a view from a nearby direction sees nearly the same silhouette. Measured on
the calibration views (``bve-mj calibrate``; pairs of views of one fruit), the normalised
errors of two views correlate by about 0.4-0.6 within 5° of each other, 0.15-0.25 at 10-15°
and not at all beyond 30°. A filter that fuses such views as independent counts one
silhouette's error several times: three views from one place claim √3 times the precision
they hold, and the planner, which likes the same best view again and again, makes that the
common case.

Model: the correlation of the errors of two views whose directions from the fruit (unit
vectors d_i, d_j) make the angle θ is

    ρ(θ) = w · exp(-(1 - cos θ) / s)       (and 1 for the same view),

a nugget 1 - w of independent error plus a von Mises-Fisher kernel on the sphere (positive
definite, smooth in the directions), fitted per component (centre, apparent radius) by
:func:`fit_view_correlation`. The nugget is independent only between views from different
places: two views from one camera position see one image (the same pixels of the same
silhouette), and twin views rendered a few millimetres apart (``benchmarks/bench_view_twins.py``)
correlate by 0.93-0.98 at 0 mm, 0.84-0.89 at 2 mm, 0.36-0.56 at 20 mm. So the nugget's share ``a``
(``nearby``) is shared by views close together, through a Matérn-3/2 kernel of the distance δ
between the camera positions (positive definite in 3-D, smooth: the planner's gradient is 0
where it stands):

    ρ = w · exp(-(1 - cos θ) / s) + (1 - w) · a · (1 + √3 δ/ℓ) exp(-√3 δ/ℓ).

A camera that holds where it is then learns (and expects to learn) almost nothing from
the view it repeats; where the camera positions are not given, the nugget is independent.

Of n views with correlation matrix C, estimating one common error-free quantity, the best
linear combination is worth n_eff = 1ᵀ C⁻¹ 1 independent views
(n for C = I, 1 when they are one view). A new view at direction e is then worth

    Δ(e) = n_eff(taken ∪ {e}) - n_eff(taken) = (1 - bᵀ C⁻¹ 1)² / (1 - bᵀ C⁻¹ b) ∈ (0, 1],

b_j = ρ(θ(e, d_j)), of a fresh one: the filter fuses it with its noise variance divided by Δ
(:func:`discounted`), the planner expects Δ times its information (``SizeInformation``). The
geometry differs from view to view, so this is an approximation (exact for the common
part of a repeated measurement); it is what keeps repeated views from shrinking the
covariance below what they know.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from bve_mj.estimation.models import BearingSizeModel, MeasurementModel, SizeModel

__all__ = [
    "TakenViews", "ViewCorrelation", "ViewShares", "discounted", "fit_view_correlation", "new_view_share",
    "shared_dof",
]  # fmt: skip

_VIEW_SETS_KEPT = 512
_MAX_NEARBY = 0.99  # a repeated view shares at most this of the nugget: C stays invertible


@dataclass(frozen=True)
class ViewCorrelation:
    """ρ(θ) = ``weight`` · exp(-(1 - cos θ) / ``width``) between two views' errors.

    Attributes:
        weight: w in [0, 1): the correlated share of a view's error variance (0: views are
            independent, the paper's assumption).
        width: s > 0, in units of 1 - cos θ (0.03 ≈ half the correlation at 12°).
        nearby: a in [0, 0.99]: the share of the rest (1 - w) that two views from one camera
            position share (0: none, the views' nugget independent wherever they are taken).
        length_m: ℓ > 0: how fast that share falls with the distance between the camera
            positions [m] (Matérn 3/2: half of it at 1.68 ℓ).
    """

    weight: float = 0.0
    width: float = 0.03
    nearby: float = 0.0
    length_m: float = 0.02

    def __post_init__(self) -> None:
        if not (math.isfinite(self.weight) and 0.0 <= self.weight < 1.0):
            raise ValueError(f"view correlation weight must be in [0, 1), got {self.weight!r}")
        if not (math.isfinite(self.width) and self.width > 0.0):
            raise ValueError(f"view correlation width must be > 0, got {self.width!r}")
        if not (math.isfinite(self.nearby) and 0.0 <= self.nearby <= _MAX_NEARBY):
            raise ValueError(f"view correlation nearby must be in [0, {_MAX_NEARBY}], got {self.nearby!r}")
        if not (math.isfinite(self.length_m) and self.length_m > 0.0):
            raise ValueError(f"view correlation length_m must be > 0, got {self.length_m!r}")

    @property
    def independent(self) -> bool:
        return self.weight == 0.0

    def half_angle_deg(self) -> float:
        """The angle at which the correlation is half its value at 0° [deg]."""
        return math.degrees(math.acos(max(-1.0, 1.0 - self.width * math.log(2.0))))

    def rho(self, cos_theta: np.ndarray) -> np.ndarray:
        """ρ's directional part for the cosines of the angles between distinct views."""
        return self.weight * np.exp(-(1.0 - np.asarray(cos_theta, dtype=float)) / self.width)

    def rho_near(self, distance_m: np.ndarray) -> np.ndarray:
        """ρ's part shared by nearby views, for the distances between their cameras [m]."""
        x = math.sqrt(3.0) * np.asarray(distance_m, dtype=float) / self.length_m
        return (1.0 - self.weight) * self.nearby * (1.0 + x) * np.exp(-x)


@dataclass(frozen=True)
class TakenViews:
    """The views taken, from unit directions (k, 3) (and, for the part nearby views share,
    camera positions (k, 3) [m]), with the inverse of their correlation matrix C and C⁻¹ 1
    made once: :meth:`share` is then called for each candidate view (the planner calls it at
    every evaluation of its objective) with one product. C = (1 - w) I + w K + (1 - w) a (N -
    I) with K and N the kernels' matrices (positive semi-definite, unit diagonal), so its
    smallest eigenvalue is at least (1 - w)(1 - a) > 0: well conditioned to invert once (a
    solve per call was most of the planner's objective where views had been taken)."""

    corr: ViewCorrelation
    directions: np.ndarray
    _Cinv: np.ndarray  # C⁻¹
    _a: np.ndarray  # C⁻¹ 1
    positions: np.ndarray | None = None  # the cameras [m], (k, 3); None: the nugget independent

    @classmethod
    def of(
        cls, corr: ViewCorrelation, directions: np.ndarray, positions: np.ndarray | None = None
    ) -> TakenViews:
        d = np.asarray(directions, dtype=float).reshape(-1, 3)
        at = None
        if positions is not None and corr.nearby > 0.0:
            at = np.asarray(positions, dtype=float).reshape(-1, 3)
            if len(at) != len(d):
                raise ValueError(f"{len(at)} camera positions for {len(d)} view directions")
        if (corr.independent and at is None) or len(d) == 0:
            return cls(corr, d, np.zeros((0, 0)), np.zeros(0), at)
        C = corr.rho(d @ d.T)
        if at is not None:
            C = C + corr.rho_near(np.linalg.norm(at[:, None, :] - at[None, :, :], axis=2))
        np.fill_diagonal(C, 1.0)
        Cinv = np.linalg.inv(C)
        return cls(corr, d, Cinv, Cinv.sum(axis=1), at)

    def share(self, e: np.ndarray, c: np.ndarray | None = None) -> tuple[float, np.ndarray]:
        """Δ(e): what a view from the unit direction ``e`` (3,) (and the camera position
        ``c`` [m], (3,)) is worth beside these views, as a share of a fresh view, and ∂Δ/∂e (3,)."""
        share, gradient, _ = self.share_at(e, c)
        return share, gradient()

    def share_at(
        self, e: np.ndarray, c: np.ndarray | None
    ) -> tuple[float, Callable[[], np.ndarray], Callable[[], np.ndarray]]:
        """Δ of a view from the unit direction ``e`` (3,) at the camera position ``c`` [m]
        (None: as if far from every view taken), with ∂Δ/∂e and ∂Δ/∂c (each (3,)) computed
        when called (the planner asks for them at about two thirds of the points it
        evaluates)."""
        zero: Callable[[], np.ndarray] = lambda: np.zeros(3)  # noqa: E731
        if not len(self._a):
            return 1.0, zero, zero
        corr = self.corr
        b_dir = corr.weight * np.exp((self.directions @ e - 1.0) / corr.width)  # ρ(e·d_j)
        near = self.positions is not None and c is not None
        if near:
            offset = np.asarray(c, dtype=float) - self.positions  # (k, 3)
            x = math.sqrt(3.0) * np.linalg.norm(offset, axis=1) / corr.length_m
            scale = (1.0 - corr.weight) * corr.nearby
            b = b_dir + scale * (1.0 + x) * np.exp(-x)
        else:
            b = b_dir
        u = self._Cinv @ b  # C⁻¹ b
        m = 1.0 - float(b @ self._a)
        s = max(1.0 - float(b @ u), 1e-12)

        def db() -> np.ndarray:  # ∂Δ/∂b = 2m (m u - s a) / s²
            return 2.0 * m * (m * u - s * self._a) / (s * s)

        def gradient_e() -> np.ndarray:  # ∂b_j/∂e = b_j d_j / width (the directional part)
            return (db() * b_dir / corr.width) @ self.directions

        def gradient_c() -> np.ndarray:  # ∂b_j/∂c = -3 scale e^(-x_j) (c - c_j) / ℓ²
            if not near:
                return np.zeros(3)
            return (db() * (-3.0 * scale * np.exp(-x) / corr.length_m**2)) @ offset

        return min(max(m * m / s, 1e-9), 1.0), gradient_e, gradient_c


def new_view_share(
    corr: ViewCorrelation,
    taken: np.ndarray,
    e: np.ndarray,
    taken_at: np.ndarray | None = None,
    c: np.ndarray | None = None,
) -> tuple[float, np.ndarray]:
    """Δ(e) and ∂Δ/∂e of a view from the unit direction ``e`` (3,) beside the views from the
    unit directions ``taken`` (k, 3) (:class:`TakenViews` when asked for many ``e``); with the
    cameras' positions of those views ``taken_at`` (k, 3) and of this one ``c`` (3,) [m], the
    part nearby views share too."""
    return TakenViews.of(corr, taken, taken_at).share(e, c)


@dataclass
class ViewShares:
    """The shares (:func:`new_view_share`) of a view's bearing and apparent size for many
    fruit and candidate views, each fruit's :class:`TakenViews` made once for its directions
    taken (the every-fruit planner scores every fruit at every candidate view: a correlation
    matrix and its inverse per score, inside a scoring that took 1.2 of a 30 ms plan with 8
    tracks)."""

    centre: ViewCorrelation
    radius: ViewCorrelation
    _made: dict[bytes, tuple[TakenViews, TakenViews]] = dataclasses.field(default_factory=dict)

    def __call__(
        self,
        taken: np.ndarray,
        e: np.ndarray,
        taken_at: np.ndarray | None = None,
        c: np.ndarray | None = None,
    ) -> tuple[float, float]:
        """(centre share, radius share) of a view from the unit direction ``e`` (3,) beside
        the views from the unit directions ``taken`` (k, 3); with their cameras' positions
        ``taken_at`` (k, 3) and this view's ``c`` (3,) [m], the nearby part counted too."""
        key = np.asarray(taken, dtype=float).reshape(-1, 3).tobytes()
        if taken_at is not None:
            key += b"@" + np.asarray(taken_at, dtype=float).reshape(-1, 3).tobytes()
        views = self._made.get(key)
        if views is None:
            if len(self._made) >= _VIEW_SETS_KEPT:  # an episode's fruit are few; a long run's not
                self._made.clear()
            views = self._made[key] = (
                TakenViews.of(self.centre, taken, taken_at), TakenViews.of(self.radius, taken, taken_at)
            )  # fmt: skip
        return views[0].share_at(e, c)[0], views[1].share_at(e, c)[0]


def shared_dof(model: MeasurementModel, dimension: int, centre_share: float, radius_share: float) -> float:
    """The degrees of freedom a view's innovation brings to the claim's innovation scale
    (:meth:`bve_mj.loop.claims.Claims.scale`): each component as the share of a fresh view
    it adds, 2Δc + Δr for a bearing/size measurement, Δr for the apparent size alone,
    ``dimension`` for any other. A discounted view's NIS is computed with the variance its
    share inflates, so it is that share of a fresh view's in expectation; counted as a whole
    view's, a camera that repeats its view would talk the scale down (its innovations are
    small because its error repeats, not because the noise is)."""
    if isinstance(model, BearingSizeModel):
        return 2.0 * centre_share + radius_share
    if isinstance(model, SizeModel):
        return radius_share
    return float(dimension)


def discounted(model: MeasurementModel, centre_share: float, radius_share: float) -> MeasurementModel:
    """``model`` (a bearing/size or size-only measurement) with its noise variances divided by
    the shares (:func:`new_view_share`) of its bearing and apparent-size components."""
    if isinstance(model, BearingSizeModel):
        g = np.sqrt([1.0 / centre_share, 1.0 / centre_share, 1.0 / radius_share])
        return dataclasses.replace(model, noise_cov_z=model.noise_cov_z * np.outer(g, g))
    if isinstance(model, SizeModel):
        return dataclasses.replace(model, variance_rad2=model.variance_rad2 / radius_share)
    raise TypeError(f"no view-correlation discount for {type(model).__name__}")


def fit_view_correlation(
    cos_theta: Sequence[float], products: Sequence[float], bins_deg: Sequence[float] | None = None
) -> ViewCorrelation:
    """Fit ρ(θ) to pairs of views of one fruit: the cosine of the angle between their
    directions and the product of their normalised errors (whose mean is the correlation).
    The products are averaged in bins of angle (heavy-tailed products would otherwise let a
    few pairs decide) and the kernel fitted to the bin means by least squares weighted by
    the pairs in each."""
    from scipy.optimize import minimize

    edges = np.radians(np.asarray(bins_deg if bins_deg is not None else _BINS_DEG, dtype=float))
    u_all = 1.0 - np.clip(np.asarray(cos_theta, dtype=float), -1.0, 1.0)
    p_all = np.asarray(products, dtype=float)
    idx = np.searchsorted(1.0 - np.cos(edges), u_all) - 1
    u, r, n = [], [], []
    for k in range(len(edges) - 1):
        sel = idx == k
        if sel.sum() >= 20:
            u.append(float(u_all[sel].mean()))
            r.append(float(p_all[sel].mean()))
            n.append(float(sel.sum()))
    if len(u) < 3:
        return ViewCorrelation()
    ua, ra, na = np.array(u), np.array(r), np.array(n)

    def loss(p: np.ndarray) -> float:
        w = 0.999 / (1.0 + math.exp(-p[0]))
        return float(np.sum(na * (ra - w * np.exp(-ua / math.exp(p[1]))) ** 2))

    starts = (3e-3, 1e-2, 3e-2, 0.1)
    fits = (minimize(loss, np.array([0.0, math.log(s0)]), method="Nelder-Mead") for s0 in starts)
    best = min(fits, key=lambda res: res.fun)
    w = 0.999 / (1.0 + math.exp(-best.x[0]))
    return ViewCorrelation(weight=round(w, 6) if w > 1e-3 else 0.0, width=float(math.exp(best.x[1])))


_BINS_DEG = (0, 2, 4, 6, 8, 10, 13, 16, 20, 25, 30, 40, 60, 90, 180)
