"""The detector's measurement noise, calibrated against ground truth (``bve-mj calibrate``).

What the detector measures of a fruit, per view: the bearing of its centre (two image
coordinates) and its apparent (equatorial) angular radius α, both in pixels (f · angle).
Their errors, measured on rendered views against the truth (:mod:`bve_mj.campaigns.calibration`):

- the apparent radius is **biased**: the outline the colour mask finds lies inside the true
  silhouette (the rim is darker and blends with what is behind it), by
  ``radius_bias_px[0] + radius_bias_px[1] · r_px / 100`` px. A bias is corrected, not
  passed off as noise: :func:`measure` adds it back.
- the variance of each is a sum of what the detector can see, with non-negative
  coefficients fitted by maximum likelihood (:func:`fit_noise_model`), in px²:

  σ² = c_floor + (c_fit + c_neighbour_fit · n) · s_fit² + c_partial · ((1 - arc/360) · r_px / 10)²
       + c_elongation · (max(k - 1, 0) · r_px / 10)² + c_scale · S + c_near · S²
       + c_neighbour · (n · r_px / 10)²,   S = (r_px / 100)²

  with s_fit the fit's own 1σ (from its residuals and how much outline it saw), arc the
  degrees of outline seen, r_px the apparent radius, k the fruit type's shape index (a plum
  hangs tilted and its outline follows the spheroid less well), and n the share of the fitted
  circle's rim where a ripe neighbour touches or overlaps the fruit (red on red shows no
  outline: the fit there rests on shading or on a neighbour's arc). Where a neighbour's rim
  runs into the outline the fit's residuals are its misfit (n · s_fit²); a lone fruit's s_fit
  overstates its error severalfold. The scale terms are the error that grows with the fruit's
  apparent size whatever the fit sees (no real fruit is the spheroid the fit assumes); a lone
  fruit's grows faster than its size as the camera closes in (S²: calibration seed 1, 0.12 px²
  at 0.10-0.15 m against 0.004 px² at 0.4-0.5 m).

- a part of the centre's error is **the fruit's own**, the same from every view: the
  silhouette of a real fruit (tilted, not quite a spheroid, shaded from above, a neighbour's
  edge beside it) puts the fitted centre a little off its true centre in the world, mostly
  vertically, and views from elsewhere do not average it out. It is bounded as a world-frame
  offset added to the centre's covariance the filter reports, whose variance as a share of
  the radius² is ``centre_offset_terms`` · (1, (k - 1)², n̄²) (:data:`OFFSET_FEATURES`: the
  shape index k and the mean neighbour share n̄ of the views fused), fitted by maximum
  likelihood over the calibration fruits and sized so that 97.1% of their offsets lie within
  its 3σ (:meth:`NoiseModel.centre_offset_cov`); where what was seen is not known, the bound
  over all fruits, σ ``centre_bias_rel`` (horizontal, vertical) times the radius
  (:meth:`NoiseModel.centre_bias_cov`).
- the rest of a view's error is shared with views **from nearby directions** (they see
  nearly the same silhouette): the correlation ρ(θ) of two views' normalised errors against
  the angle between them, fitted per component (:mod:`bve_mj.estimation.view_correlation`;
  ``centre_correlation``, ``radius_correlation``). The filter and the planner count a view
  near the views already fused as the share of a fresh view it is worth.
- some fruits are **hard** (tilted and elongated, cut by neighbours): the detector refuses
  most views of them, and the views it fits err several times what the model, fitted over
  all fruits, says, the same way from nearby directions (an episode's few views share it
  and agree: their innovations do not show it). The refusals do show it: the calibration
  fruits' mean squared normalised error grows as exp(b · refused share) (``refusal_scale``
  b, fitted), and an episode's claimed covariance grows with it
  (:class:`bve_mj.loop.claims.Claims`).
- a few views err **eight times** the model's σ, and nothing the detector reports tells which
  (in truss scenes one in thirty of the every-fruit detector's: a fit along a neighbour's
  edge). The every-fruit tracker fuses each view under a scale mixture, a share
  ``outlier_share`` of views erring ``outlier_scale`` times the σ
  (:mod:`bve_mj.estimation.outliers`), fitted to the neighbours' rows of ``bve-mj calibrate
  --every-fruit``.
- the errors are **heavy-tailed**: the claim is a Student-t (:mod:`bve_mj.estimation.
  claim_shape`) whose covariance is m (``moment_scale``) and whose 99.9% bound is κ²
  (``tail_scale``) times the claim before them (the radius' variance m_r times,
  ``radius_moment_scale``), fitted on episode-like estimates (3-6 calibration views of a fruit
  fused and claimed as the loop does: :mod:`~bve_mj.estimation.noise_tail`).

The fitted model is a JSON file; the package ships one (``default``), settings name it
(``measurement.noise_model``), and one made with another camera is refused."""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, replace
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from bve_mj.config import CameraConfig
from bve_mj.errors import ConfigError
from bve_mj.estimation.claim_shape import ClaimShape
from bve_mj.estimation.outliers import OutlierMixture
from bve_mj.estimation.view_correlation import ViewCorrelation

__all__ = [
    "FEATURES",
    "INNOVATION_PRIOR_DOF",
    "OFFSET_FEATURES",
    "NoiseModel",
    "Outline",
    "load_noise_model",
]

FEATURES = ("floor", "fit", "partial", "elongation", "scale", "neighbour", "neighbour_fit", "near")

"""The variance terms, in the order of the coefficients. A model file from before the later
terms were added holds the first four or six: the others count 0 in it."""


OFFSET_FEATURES = ("floor", "shape", "neighbour")

"""The terms of the fruit's own centre offset's variance, in the order of
``NoiseModel.centre_offset_terms``."""


INNOVATION_PRIOR_DOF = 6.0

"""How much the noise model's word counts against a fruit's own innovations (degrees of
freedom, :class:`bve_mj.loop.claims.Claims`; the calibration's tail scale claims as the loop
does)."""

_KIND = "bve_mj detector noise model"


@dataclass(frozen=True)
class Outline:
    """What the detector saw of a fruit's outline in one view.

    Attributes:
        neighbour_share: the share of the fitted circle's rim where a ripe neighbour touches
            or overlaps the fruit (0-1).
    """

    neighbour_share: float = 0.0


_CORRELATIONS = ("centre_correlation", "radius_correlation")
_MOMENTS = ("moment_scale", "view_moment_scale", "radius_moment_scale")


@dataclass(frozen=True, kw_only=True)
class NoiseModel:
    """Calibrated noise of the detector's centre and apparent radius [px].

    Attributes:
        centre_var_px2: coefficients of the centre's variance per image coordinate, (8,), in
            the order of :data:`FEATURES`.
        radius_var_px2: coefficients of the apparent radius' variance, (8,).
        radius_bias_px: the apparent radius' bias b0 + b1 · r_px / 100 [px], (2,).
        typical_fit_px: the median fit σ seen in calibration: what a planner expects of a
            view it has not taken yet [px].
        centre_bias_rel: σ of the fruit's own world-frame offset of the fitted centre,
            horizontal and vertical, as shares of its radius.
        width_px, height_px, hfov_deg: the camera it was calibrated with.
        samples: detections it was fitted to.
        source: how it was made (the command and its seeds).
        centre_correlation, radius_correlation: how the per-view errors of the centre and
            of the apparent radius correlate between views of one fruit from nearby
            directions (independent in a file that does not say).
        refusal_scale: b ≥ 0, a fruit's error variance against the share of its views the
            detector refused: × exp(b · share) (0 in a file that does not say).
        tail_scale, moment_scale: κ² ≥ 1 and m ≤ κ²: the claim (a Student-t, :attr:`claim_shape`)
            before them times κ² is its bound, whose 99.9% ellipsoid holds 99.9% of the errors
            of episode-like estimates from the calibration views, and times m its covariance,
            their second moment (κ² 1 and m None, Gaussian, in a file that does not say).
        view_tail_scale, view_moment_scale: the same of single views (their own offset bounded
            over all fruits): what size-only (range) episodes claim with.
        radius_moment_scale: m_r > 0, the same of the radius alone in the episode-like
            estimates (None, as the centre's, in a file that does not say). Size-only episodes
            claim the radius as the centre: it is estimated with the range, from the same sizes.
        centre_offset_terms: coefficients (3,) of the fruit's own offset's variance [share of
            the radius²] on :data:`OFFSET_FEATURES`, or () (a file that does not say): the
            offset is then ``centre_bias_rel`` whatever was seen.
        partial_colour_offset: the fruit's own offset's variance [share of the radius²] added
            where the detector fits fruit coloured in part (a ``detector.ripe_class`` short of
            red: the fit follows the coloured cap's edge), shaped as ``centre_bias_rel``
            (:mod:`bve_mj.estimation.partial_colour`; 0 in a file that does not say).
        partial_colour_view: the same detector's views: (δ, k_c, k_r), its apparent radius
            δ px further below the bias above, and the variances of its centre and apparent
            radius k_c and k_r times the model's ((0, 1, 1) in a file that does not say).
        outlier_share, outlier_scale: the views' own errors as a scale mixture: a share π of
            them err κ times the σ above (:mod:`bve_mj.estimation.outliers`; the tracker
            fuses with it). π = 0 (a file that does not say): Gaussian.
    """

    centre_var_px2: tuple[float, ...]
    radius_var_px2: tuple[float, ...]
    radius_bias_px: tuple[float, float]
    typical_fit_px: float
    centre_bias_rel: tuple[float, float]
    width_px: int
    height_px: int
    hfov_deg: float
    samples: int
    source: str = ""
    centre_correlation: ViewCorrelation = field(default_factory=ViewCorrelation)
    radius_correlation: ViewCorrelation = field(default_factory=ViewCorrelation)
    refusal_scale: float = 0.0
    tail_scale: float = 1.0
    view_tail_scale: float = 1.0
    moment_scale: float | None = None
    view_moment_scale: float | None = None
    radius_moment_scale: float | None = None
    centre_offset_terms: tuple[float, ...] = ()
    partial_colour_offset: float = 0.0
    partial_colour_view: tuple[float, float, float] = (0.0, 1.0, 1.0)
    outlier_share: float = 0.0
    outlier_scale: float = 1.0

    def __post_init__(self) -> None:
        OutlierMixture(self.outlier_share, self.outlier_scale)  # raises ValueError naming it
        for name in ("centre_var_px2", "radius_var_px2"):
            v = getattr(self, name)
            if len(v) != len(FEATURES) or not all(math.isfinite(x) and x >= 0.0 for x in v) or not any(v):
                raise ValueError(f"{name} must be {len(FEATURES)} finite numbers >= 0, not all 0")
        if len(self.radius_bias_px) != 2 or not all(math.isfinite(x) for x in self.radius_bias_px):
            raise ValueError("radius_bias_px must be 2 finite numbers")
        if not (math.isfinite(self.typical_fit_px) and self.typical_fit_px > 0.0):
            raise ValueError("typical_fit_px must be > 0")
        if len(self.centre_bias_rel) != 2 or not all(
            math.isfinite(x) and x >= 0.0 for x in self.centre_bias_rel
        ):
            raise ValueError("centre_bias_rel must be 2 finite numbers >= 0")
        for name in ("refusal_scale", "partial_colour_offset"):
            if not (math.isfinite(getattr(self, name)) and getattr(self, name) >= 0.0):
                raise ValueError(f"{name} must be a finite number >= 0")
        for name in ("tail_scale", "view_tail_scale"):
            if not (math.isfinite(getattr(self, name)) and getattr(self, name) >= 1.0):
                raise ValueError(f"{name} must be a finite number >= 1")
        _ = (self.claim_shape, self.view_claim_shape)  # raise ValueError naming a moment scale
        v = self.partial_colour_view
        if len(v) != 3 or not all(math.isfinite(x) for x in v) or min(v[1:]) <= 0.0:
            raise ValueError("partial_colour_view must be 3 finite numbers, the last two > 0")
        n, terms = len(OFFSET_FEATURES), self.centre_offset_terms
        if terms and (len(terms) != n or not all(math.isfinite(x) and x >= 0.0 for x in terms)):
            raise ValueError(f"centre_offset_terms must be {n} finite numbers >= 0, or none")

    @property
    def claim_shape(self) -> ClaimShape:
        """The shape of an episode's claim (camera measurement): ρ = κ²/m, Gaussian without m."""
        return ClaimShape.of_scales(
            self.tail_scale, self.moment_scale, "moment_scale", self.radius_moment_scale
        )

    @property
    def view_claim_shape(self) -> ClaimShape:
        """The same with the single views' tail (size-only episodes claim with it)."""
        return ClaimShape.of_scales(self.view_tail_scale, self.view_moment_scale, "view_moment_scale")

    @property
    def outliers(self) -> OutlierMixture:
        """The views' share π of outliers and their scale κ."""
        return OutlierMixture(self.outlier_share, self.outlier_scale)

    def centre_bias_cov(self, radius_m: float) -> np.ndarray:
        """The covariance [m²] (3, 3) of the fruit's own offset of the fitted centre, world frame
        (z vertical), for a fruit of radius ``radius_m``."""
        h, v = self.centre_bias_rel
        return np.diag([(h * radius_m) ** 2, (h * radius_m) ** 2, (v * radius_m) ** 2])

    @staticmethod
    def offset_features(shape_index: float, outlines: Sequence[Outline]) -> np.ndarray:
        """The terms of :data:`OFFSET_FEATURES` for a fruit of ``shape_index`` seen as
        ``outlines`` (one per view fused), (3,).

        Only what belongs to the fruit (its type's shape, its neighbours), not how much of its
        outline the views saw: an episode picks its views, and a beefsteak seen whole from
        three was still 0.7% of its radius off vertically (seed 6262, 3090971832)."""
        neighbour = float(np.mean([min(max(o.neighbour_share, 0.0), 1.0) for o in outlines]))
        return np.array([1.0, (shape_index - 1.0) ** 2, neighbour**2])

    def centre_offset_cov(
        self, radius_m: float, shape_index: float, outlines: Sequence[Outline | None]
    ) -> np.ndarray:
        """The covariance [m²] (3, 3) of the own offset of a fruit of radius ``radius_m`` and
        ``shape_index`` whose fused views saw ``outlines``: the bound over all fruits
        (:meth:`centre_bias_cov`) unless the model is conditioned and every outline is known;
        then its fitted share of the radius², shaped (horizontal, vertical) as that bound."""
        known = [o for o in outlines if o is not None]
        if not self.centre_offset_terms or not known or len(known) != len(outlines):
            return self.centre_bias_cov(radius_m)
        share = float(np.dot(self.centre_offset_terms, self.offset_features(shape_index, known)))
        h, v = self.centre_bias_rel
        mean = (2.0 * h * h + v * v) / 3.0
        if mean <= 0.0:
            return np.zeros((3, 3))
        return np.diag([h * h, h * h, v * v]) * (share / mean) * radius_m**2

    @staticmethod
    def features(
        radius_px: float, arc_deg: float, fit_px: float, shape_index: float, neighbour_share: float = 0.0
    ) -> np.ndarray:
        """The variance terms of :data:`FEATURES` for one view, (8,): the fit's own σ² also
        times the neighbour share n (a neighbour's rim in the outline: the fit's residuals are
        its misfit), and the scale (r_px/100)² also squared (a close view's)."""
        n, r = min(max(neighbour_share, 0.0), 1.0), radius_px / 10.0
        partial, elongation = max(0.0, 1.0 - arc_deg / 360.0) * r, max(shape_index - 1.0, 0.0) * r
        scale = (radius_px / 100.0) ** 2
        return np.array(
            [1.0, fit_px**2, partial**2, elongation**2, scale, (n * r) ** 2, n * fit_px**2, scale**2]
        )

    def for_partial_colour(self) -> NoiseModel:
        """The model of a detector whose ripe class is short of red: ``partial_colour_view``'s
        bias and variance scales applied to every view (and then spent: (0, 1, 1))."""
        d, kc, kr = self.partial_colour_view
        return replace(
            self, centre_var_px2=tuple(kc * x for x in self.centre_var_px2),
            radius_var_px2=tuple(kr * x for x in self.radius_var_px2),
            radius_bias_px=(self.radius_bias_px[0] + d, self.radius_bias_px[1]),
            partial_colour_view=(0.0, 1.0, 1.0),
        )  # fmt: skip

    def radius_bias(self, radius_px: float) -> float:
        """How much smaller the detector sees the apparent radius than it is [px] (negative)."""
        return self.radius_bias_px[0] + self.radius_bias_px[1] * radius_px / 100.0

    def sigmas_px(
        self,
        radius_px: float,
        arc_deg: float,
        centre_fit_px: float,
        radius_fit_px: float,
        shape_index: float,
        neighbour_share: float = 0.0,
    ) -> tuple[float, float]:
        """1σ of each image coordinate of the centre and of the apparent radius [px]."""
        fc = self.features(radius_px, arc_deg, centre_fit_px, shape_index, neighbour_share)
        fr = self.features(radius_px, arc_deg, radius_fit_px, shape_index, neighbour_share)
        centre, radius = float(np.dot(self.centre_var_px2, fc)), float(np.dot(self.radius_var_px2, fr))
        return math.sqrt(centre), math.sqrt(radius)

    def expected_sigmas_px(self, radius_px: float, shape_index: float) -> tuple[float, float]:
        """The σ a view of a whole fruit of apparent radius ``radius_px`` is expected to have
        (the planner's model of a view not yet taken)."""
        fit = self.typical_fit_px
        return self.sigmas_px(radius_px, 360.0, fit, fit, shape_index)

    def check_camera(self, camera: CameraConfig, name: str) -> None:
        """Raise :class:`ConfigError` naming ``name`` unless calibrated for ``camera``."""
        if (self.width_px, self.height_px) != (camera.width_px, camera.height_px) or not math.isclose(
            self.hfov_deg, math.degrees(camera.hfov_rad), abs_tol=0.01
        ):
            raise ConfigError(
                "measurement.noise_model",
                name,
                f"a noise model calibrated for this camera ({camera.width_px}x{camera.height_px}, "
                f"{math.degrees(camera.hfov_rad):.1f} deg); it is for {self.width_px}x{self.height_px}, "
                f"{self.hfov_deg:.1f} deg: run bve-mj calibrate",
            )

    def to_json(self) -> dict[str, Any]:
        """The file's content (:func:`load_noise_model` reads it back)."""
        return {"kind": _KIND, "version": 5, "features": list(FEATURES), **asdict(self)}


def _default_path() -> Path:
    return Path(str(resources.files("bve_mj") / "data" / "noise_model.json"))


def load_noise_model(name: str = "default") -> NoiseModel:
    """The noise model ``name``: ``default`` (shipped with the package) or a JSON file made by
    ``bve-mj calibrate``.

    Raises:
        ConfigError: naming the file, when it is missing, not JSON or not a noise model.
    """
    path = _default_path() if name == "default" else Path(name)
    field = "measurement.noise_model"
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        reason = exc.strerror if isinstance(exc, OSError) else "not text"
        raise ConfigError(
            field, name, f"a readable noise model file from bve-mj calibrate ({reason})"
        ) from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ConfigError(field, name, f"a JSON noise model file (line {exc.lineno}: {exc.msg})") from None
    if not isinstance(data, dict) or data.get("kind") != _KIND:
        raise ConfigError(field, name, "a noise model file written by bve-mj calibrate")
    terms = data.get("features")
    if not isinstance(terms, list) or not terms or terms != list(FEATURES[: len(terms)]):
        raise ConfigError(field, name, f"a noise model with the terms {', '.join(FEATURES)}")
    pad = (0.0,) * (len(FEATURES) - len(terms))  # an older file: the terms it lacks count 0
    keys = {f for f in NoiseModel.__dataclass_fields__}
    try:
        values = {k: data[k] for k in keys if k in data}
        return NoiseModel(
            **{
                **values,
                "centre_var_px2": (*(float(x) for x in values["centre_var_px2"]), *pad),
                "radius_var_px2": (*(float(x) for x in values["radius_var_px2"]), *pad),
                "radius_bias_px": tuple(float(x) for x in values["radius_bias_px"]),
                "centre_bias_rel": tuple(float(x) for x in values["centre_bias_rel"]),
                "refusal_scale": float(values.get("refusal_scale", 0.0)),
                "tail_scale": float(values.get("tail_scale", 1.0)),
                "view_tail_scale": float(values.get("view_tail_scale", values.get("tail_scale", 1.0))),
                **{k: None if values.get(k) is None else float(values[k]) for k in _MOMENTS},
                "centre_offset_terms": tuple(float(x) for x in values.get("centre_offset_terms", ())),
                "partial_colour_offset": float(values.get("partial_colour_offset", 0.0)),
                "partial_colour_view": tuple(float(x) for x in values.get("partial_colour_view", (0, 1, 1))),
                "outlier_share": float(values.get("outlier_share", 0.0)),
                "outlier_scale": float(values.get("outlier_scale", 1.0)),
                **{k: ViewCorrelation(**values[k]) for k in _CORRELATIONS if k in values},
            }
        )
    except (KeyError, TypeError, ValueError) as exc:
        raise ConfigError(field, name, f"a complete noise model ({type(exc).__name__}: {exc})") from None
