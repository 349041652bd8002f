"""Settings of the camera, the fruit prior, the measurement and the filter."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from bve_mj.config.fields import (
    FilterKind,
    MeasurementKind,
    StateKind,
    _between,
    _choice,
    _non_negative,
    _number,
    _open_interval,
    _positive,
    _positive_int,
    _why,
)
from bve_mj.config.scene import SceneConfig
from bve_mj.errors import ConfigError

__all__ = ["CameraConfig", "FilterConfig", "FruitPrior", "MeasurementConfig"]


@dataclass(frozen=True, kw_only=True)
class CameraConfig:
    """The eye-in-hand camera's image geometry (pinhole, square pixels)."""

    hfov_rad: float = field(
        default=math.radians(69.0),
        metadata=_why("OAK-1, the camera the authors used on this arm: 69 deg horizontal", "rad"),
    )
    width_px: int = field(default=640, metadata=_why("OAK-1 preview resolution", "px"))
    height_px: int = field(default=480, metadata=_why("OAK-1 preview resolution", "px"))
    blur_sigma_px: float = field(
        default=0.5,
        metadata=_why(
            "the lens and sensor's point spread (Gaussian sigma) applied to every rendered image: "
            "edges blend over a pixel or two as a real camera's do. It replaces the renderer's "
            "multisample anti-aliasing, which doubles the cost of a frame on a CPU (25 -> 12 ms); "
            "0 = hard pixel edges",
            "px",
        ),
    )

    def __post_init__(self) -> None:
        _open_interval("camera", "hfov_rad", self.hfov_rad, 0.0, math.pi, "a number in (0, pi)")
        _positive_int("camera", "width_px", self.width_px, 8192)
        _positive_int("camera", "height_px", self.height_px, 8192)
        if not 0.0 <= _number("camera", "blur_sigma_px", self.blur_sigma_px) <= 5.0:
            raise ConfigError("camera.blur_sigma_px", self.blur_sigma_px, "a number in [0, 5]")

    @property
    def focal_px(self) -> float:
        """Focal length [px] from the horizontal field of view."""
        return 0.5 * self.width_px / math.tan(0.5 * self.hfov_rad)

    @property
    def vfov_rad(self) -> float:
        """Vertical field of view [rad]."""
        return 2.0 * math.atan(0.5 * self.height_px / self.focal_px)


@dataclass(frozen=True, kw_only=True)
class FruitPrior:
    """What the estimator assumes of a tomato (it never knows the true radius)."""

    radius_m: float = field(
        default=0.035,
        metadata=_why("r_k: middle of greenhouse tomato radii 25-45 mm", "m"),
    )
    radius_spread_rel: float = field(
        default=0.15,
        metadata=_why(
            "the true radius is known only to +-15% (uniform): sigma = 0.15/sqrt(3) = 8.7% of range"
        ),
    )

    shape_spread_rel: float = field(
        default=0.0,
        metadata=_why(
            "non-spherical fruit: the apparent radius varies over viewing directions by +-this share "
            "(uniform; e.g. 0.1 for a 1 : 1 : 0.8 spheroid), added to the range variance; 0 = spheres"
        ),
    )

    shape_index: float = field(
        default=1.0,
        metadata=_why(
            "the shape index (height / width) the detector's spheroid fit starts from and is held "
            "to where a view cannot see it (along the fruit's axis)"
        ),
    )

    tilt_sigma_deg: float = field(
        default=4.0,
        metadata=_why(
            "the fruit's axis leans from the vertical on its peduncle by a few degrees: the "
            "detector's spheroid fit estimates the lean across the line of sight, held to 0 with "
            "this sigma (the simulated crop leans 0-8 deg: 3.3 deg rms per direction); 0 = upright",
            "deg",
        ),
    )

    def __post_init__(self) -> None:
        _positive("fruit", "radius_m", self.radius_m)
        if not (
            isinstance(self.tilt_sigma_deg, (int, float))
            and not isinstance(self.tilt_sigma_deg, bool)
            and math.isfinite(self.tilt_sigma_deg)
            and 0.0 <= self.tilt_sigma_deg <= 30.0
        ):
            raise ConfigError("fruit.tilt_sigma_deg", self.tilt_sigma_deg, "a number in [0, 30]")
        if not (isinstance(self.shape_index, (int, float)) and 0.4 <= self.shape_index <= 2.5):
            raise ConfigError("fruit.shape_index", self.shape_index, "a number in [0.4, 2.5]")
        for name in ("radius_spread_rel", "shape_spread_rel"):
            value = getattr(self, name)
            _non_negative("fruit", name, value)
            if value >= 1.0:
                raise ConfigError(f"fruit.{name}", value, "a number in [0, 1)")

    @classmethod
    def for_scene(cls, scene: SceneConfig) -> FruitPrior:
        """What the estimator assumes of a fruit of ``scene``'s type: the middle of its radius
        range ± half its width, the middle of its shape-index range, and a shape spread of
        half the largest departure of its shape index from 1 (a spheroid looks up to that
        much larger or smaller than its equator)."""
        lo, hi = scene.radius_range_m
        s_lo, s_hi = scene.shape_index_range
        return cls(
            radius_m=0.5 * (lo + hi),
            radius_spread_rel=min((hi - lo) / (hi + lo), 0.99),
            shape_spread_rel=min(0.5 * max(abs(1.0 - s_lo), abs(1.0 - s_hi)), 0.99),
            shape_index=min(max(0.5 * (s_lo + s_hi), 0.4), 2.5),
        )

    @property
    def tilt_sigma_rad(self) -> float:
        """σ of the angle the fruit's axis leans by in any one direction [rad]."""
        return math.radians(self.tilt_sigma_deg)

    @property
    def size_spread_rel(self) -> float:
        """Standard deviation of the apparent size's relative error from the unknown radius and
        shape: uniform ±s each, s/√3, combined in quadrature."""
        return math.hypot(self.radius_spread_rel, self.shape_spread_rel) / math.sqrt(3.0)


@dataclass(frozen=True, kw_only=True)
class MeasurementConfig:
    """What the filter measures, and the camera-frame covariance Σc it measures it with.

    Σc is derived from the camera, not invented (see :meth:`Settings.sigma_c_m2`): at the
    reference range ρ the lateral σ is ρ·σ_px/f, and the range σ combines the unknown
    true radius with the pixel error of the apparent radius. ``sigma_c_m2`` overrides the
    derivation with an explicit 3x3 (or diagonal) covariance in the camera frame.
    """

    kind: MeasurementKind = field(
        default="auto",
        metadata=_why(
            "auto: range in the synthetic world (the paper's EKF), camera (bearing + range) in the "
            "rendered closed loop, where range alone cannot recover from the unknown fruit radius"
        ),
    )
    centre_sigma_px: float = field(
        default=1.0,
        metadata=_why("blob-centre error: sub-pixel fit plus segmentation bias and calibration", "px"),
    )
    radius_sigma_px: float = field(
        default=0.5, metadata=_why("apparent-radius error of a circle fit to the blob edge", "px")
    )
    reference_range_m: float | None = field(
        default=None,
        metadata=_why(
            "Σc is taken at this range. Unset: the world's preset: the protocol's l_dist in the "
            "synthetic world, the band distance (constraints.band_distance_m) in MuJoCo",
            "m",
        ),
    )
    sigma_c_m2: tuple[tuple[float, ...], ...] | None = field(
        default=None, metadata=_why("explicit Σc (camera frame, x = depth); None derives it", "m^2")
    )
    noise_model: str = field(
        default="default",
        metadata=_why(
            "with the radius in the state (filter.state): the detector's calibrated noise, default "
            "(shipped) or a JSON file from bve-mj calibrate; centre_sigma_px and radius_sigma_px "
            "are then not used"
        ),
    )

    def __post_init__(self) -> None:
        _choice("measurement", "kind", self.kind, MeasurementKind)
        if not isinstance(self.noise_model, str) or not self.noise_model.strip():
            raise ConfigError("measurement.noise_model", self.noise_model, "default or a JSON file path")
        _between("measurement", "centre_sigma_px", self.centre_sigma_px, 1e-3, 1e3)
        _between("measurement", "radius_sigma_px", self.radius_sigma_px, 1e-3, 1e3)
        if self.reference_range_m is not None:
            _between("measurement", "reference_range_m", self.reference_range_m, 0.01, 100.0)
        if self.sigma_c_m2 is not None:
            object.__setattr__(self, "sigma_c_m2", _covariance("measurement.sigma_c_m2", self.sigma_c_m2))


def _covariance(name: str, value: Any) -> tuple[tuple[float, ...], ...]:
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ConfigError(name, value, "a 3x3 symmetric positive-definite matrix or 3 variances") from None
    if arr.shape == (3,):
        arr = np.diag(arr)
    if arr.shape != (3, 3) or not np.all(np.isfinite(arr)) or not np.allclose(arr, arr.T):
        raise ConfigError(name, value, "a 3x3 symmetric positive-definite matrix or 3 variances")
    try:
        np.linalg.cholesky(arr)
    except np.linalg.LinAlgError:
        raise ConfigError(name, value, "a positive-definite matrix (all eigenvalues > 0)") from None
    return tuple(tuple(float(x) for x in row) for row in arr)


@dataclass(frozen=True, kw_only=True)
class FilterConfig:
    """The filter: EKF or UKF over the fruit's state; static fruit (F = I), process noise Q,
    prior P0, optional NIS gating."""

    kind: FilterKind = field(
        default="ekf",
        metadata=_why("ekf (the paper's), or ukf (unscented: no Jacobians, sigma points through h)"),
    )
    state: StateKind = field(
        default="auto",
        metadata=_why(
            "centre: the paper's 3-D state, the range from the apparent size with the radius the prior "
            "assumes; centre_radius: the fruit's radius in the state too, measured as bearing and "
            "apparent angular size (calibration biases too, when the sensor declares them); auto: "
            "centre in the synthetic world (the paper's table), centre_radius in MuJoCo"
        ),
    )
    iterations: int | None = field(
        default=None,
        metadata=_why(
            "linearisations per update (1 = the EKF or UKF; more = the iterated EKF, which linearises "
            "again at the updated mean, or the UKF's posterior linearisation: a bearing seen from a "
            "prior 5 cm off along the ray is otherwise fused 1-2 mm off the ray it measured). None: "
            "1 for the centre state (the paper's), 10 with the radius in the state"
        ),
    )

    @property
    def ekf_iterations(self) -> int:
        """``iterations`` with None resolved for the state."""
        if self.iterations is not None:
            return self.iterations
        return 10 if self.state == "centre_radius" else 1

    process_sigma_m: float = field(
        default=0.0,
        metadata=_why(
            "Q = sigma^2 I per step; 0: the fruit is static and the synthetic world has no model "
            "error (1 mm made the camera-mode filter conservative, NEES 1.7, and twice as wrong)",
            "m",
        ),
    )
    initial_sigma_m: float = field(
        default=0.15 / math.sqrt(3.0),
        metadata=_why("P0: std of the protocol's U[-0.15, 0.15] m initial error per axis", "m"),
    )
    gate_probability: float | None = field(
        default=None,
        metadata=_why(
            "NIS gate (chi-square probability). Unset: the world's preset: off in the paper's "
            "Gaussian protocol; in MuJoCo one that rejects false detections (NIS in the thousands) "
            "but not the true ones a wrong fruit-radius guess biases in range (NIS up to ~20 seen "
            "at 0.999)"
        ),
    )

    reset_after_rejections: int = field(
        default=3,
        metadata=_why(
            "with gating: when this many measurements in a row are gated out but agree with each "
            "other, the belief had locked onto something wrong (a false detection fused early): "
            "it is reopened to P0 and they are fused"
        ),
    )

    def __post_init__(self) -> None:
        _choice("filter", "kind", self.kind, FilterKind)
        _choice("filter", "state", self.state, StateKind)
        if self.iterations is not None:
            _positive_int("filter", "iterations", self.iterations, 100)
            if self.iterations > 100:
                raise ConfigError("filter.iterations", self.iterations, "an integer in [1, 100] or none")
        _non_negative("filter", "process_sigma_m", self.process_sigma_m)
        _positive("filter", "initial_sigma_m", self.initial_sigma_m)
        _positive_int("filter", "reset_after_rejections", self.reset_after_rejections, 100)
        if self.gate_probability is not None:
            _open_interval(
                "filter",
                "gate_probability",
                self.gate_probability,
                0.0,
                1.0,
                "a number in (0, 1) or none",
            )
