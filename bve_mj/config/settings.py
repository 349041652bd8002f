"""All sections together: :class:`Settings`, loading from TOML (unknown names get a "did you
mean"), and :func:`describe`.

Presets: ``Settings()`` leaves the world-dependent settings unset; a runner resolves them for
its world (:meth:`Settings.for_world`) from the one table of :mod:`bve_mj.config.presets`.
:meth:`Settings.paper` (the synthetic protocol's) and :meth:`Settings.greenhouse` (the MuJoCo
closed loop's) are the defaults so resolved. A TOML file sets only what it changes, in the
section that owns it; keys that moved (:data:`MOVED_KEYS`) are still read, with a
:class:`~bve_mj.errors.SettingMovedWarning` (a :class:`DeprecationWarning`) naming the new key.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import sys
import warnings
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, get_args

import numpy as np

from bve_mj.config.detector import DetectorConfig
from bve_mj.config.episode import EpisodeConfig, FaultConfig
from bve_mj.config.fields import WorldName
from bve_mj.config.moved import MOVED_KEYS, move_keys
from bve_mj.config.planning import ConstraintConfig, PlannerConfig, ProtocolConfig, RobotConfig
from bve_mj.config.presets import PRESETS
from bve_mj.config.scene import SceneConfig, SensorConfig
from bve_mj.config.sensing import CameraConfig, FilterConfig, FruitPrior, MeasurementConfig
from bve_mj.config.tracking import TrackingConfig
from bve_mj.errors import ConfigError, SettingMovedWarning

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

__all__ = [
    "MOVED_KEYS",
    "SECTIONS",
    "Settings",
    "describe",
    "load_settings",
    "settings_from_dict",
    "settings_to_dict",
    "with_overrides",
]


@dataclass(frozen=True, kw_only=True)
class Settings:
    """Every setting of a run, by section; the world-dependent ones left unset until a runner
    resolves them for its world (:meth:`for_world`)."""

    camera: CameraConfig = field(default_factory=CameraConfig)
    fruit: FruitPrior = field(default_factory=FruitPrior)
    measurement: MeasurementConfig = field(default_factory=MeasurementConfig)
    filter: FilterConfig = field(default_factory=FilterConfig)
    constraints: ConstraintConfig = field(default_factory=ConstraintConfig)
    planner: PlannerConfig = field(default_factory=PlannerConfig)
    protocol: ProtocolConfig = field(default_factory=ProtocolConfig)
    robot: RobotConfig = field(default_factory=RobotConfig)
    scene: SceneConfig = field(default_factory=SceneConfig)
    sensor: SensorConfig = field(default_factory=SensorConfig)
    detector: DetectorConfig = field(default_factory=DetectorConfig)
    episode: EpisodeConfig = field(default_factory=EpisodeConfig)
    faults: FaultConfig = field(default_factory=FaultConfig)
    tracking: TrackingConfig = field(default_factory=TrackingConfig)

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            expected = SECTIONS[f.name]
            if not isinstance(value, expected):
                raise ConfigError(f.name, value, f"a {expected.__name__}")

    @classmethod
    def paper(cls) -> Settings:
        """The paper's synthetic protocol: the defaults resolved for the synthetic world (range
        EKF, 3-D state, no gate, band 1 ± 0.1 m, 0.2 m steps, Σc at 1 m), as ``bve-mj paper``
        runs them."""
        return cls().for_world("synthetic")

    @classmethod
    def greenhouse(cls) -> Settings:
        """The MuJoCo closed loop: the defaults resolved for the MuJoCo world (camera
        measurement, the radius in the state, NIS gate 0.99999, band 0.30 ± 0.08 m, 0.10 m
        steps, Σc at the band distance, the scene's fruit prior), as ``bve-mj episode`` runs
        them (approach mode adapts them further: :func:`bve_mj.loop.mujoco.episode_settings`)."""
        return cls().for_world("mujoco")

    def sigma_c_m2(self) -> np.ndarray:
        """Σc, the camera-frame measurement covariance [m²] (x = depth, y/z lateral), (3, 3).

        Derived at the reference range ρ (1 m): lateral σ = ρ·σ_centre/f; range from the
        angular radius of a sphere, ρ = r / sin α, so σ_ρ/ρ combines the relative spread
        of the true radius (uniform ±s: s/√3) with the relative pixel error of the
        apparent radius (σ_r/r_px, r_px = f·tan α).
        """
        m = self.measurement
        if m.sigma_c_m2 is not None:
            return np.array(m.sigma_c_m2, dtype=float)
        rho = self.reference_range_m
        f = self.camera.focal_px
        sigma_lateral = rho * m.centre_sigma_px / f
        alpha = math.asin(min(self.fruit.radius_m / rho, 1.0))
        radius_px = f * math.tan(alpha)
        rel = math.hypot(self.fruit.size_spread_rel, m.radius_sigma_px / radius_px)
        sigma_range = rho * rel
        return np.diag([sigma_range**2, sigma_lateral**2, sigma_lateral**2])

    def for_world(self, world: WorldName) -> Settings:
        """These settings with the world-dependent defaults resolved. Every runner calls this
        first, so the Python API, the CLI and campaigns agree:

        - every setting left unset (``"auto"``, or ``None`` for a number) that the world's
          preset names takes its value from :data:`bve_mj.config.presets.PRESETS`:
          ``measurement.kind``, ``filter.state``, ``filter.gate_probability``, the distance band
          and step limit of ``constraints``, ``measurement.reference_range_m``,
          ``planner.upright_weight``;
        - in MuJoCo, a ``fruit`` section left at its defaults (the paper's r_k = 35 mm ±15%)
          becomes the prior of the scene's fruit type (:meth:`FruitPrior.for_scene`): the
          estimator knows the variety it is picking, not each fruit's size. Any value set in
          ``[fruit]`` keeps the whole section as given.

        Resolving twice for one world changes nothing.
        """
        if world not in get_args(WorldName):
            raise ConfigError("world", world, "one of " + ", ".join(get_args(WorldName)))
        if world == "synthetic" and self.filter.state == "centre_radius":
            raise ConfigError(
                "filter.state",
                self.filter.state,
                "auto or centre in the synthetic world (it measures the centre, not an image: "
                "centre_radius needs the MuJoCo world)",
            )
        p = PRESETS[world]
        c, m, f = self.constraints, self.measurement, self.filter
        constraints = dataclasses.replace(
            c,
            band_distance_m=p.band_distance_m if c.band_distance_m is None else c.band_distance_m,
            band_tolerance_m=p.band_tolerance_m if c.band_tolerance_m is None else c.band_tolerance_m,
            step_m=p.step_m if c.step_m is None else c.step_m,
        )
        reference = p.reference_range_m if p.reference_range_m is not None else constraints.band_distance_m
        out = dataclasses.replace(
            self,
            constraints=constraints,
            measurement=dataclasses.replace(
                m,
                kind=p.measurement_kind if m.kind == "auto" else m.kind,
                reference_range_m=reference if m.reference_range_m is None else m.reference_range_m,
            ),
            filter=dataclasses.replace(
                f,
                state=p.state if f.state == "auto" else f.state,
                gate_probability=p.gate_probability if f.gate_probability is None else f.gate_probability,
            ),
        )
        if self.planner.upright_weight is None:
            out = dataclasses.replace(
                out, planner=dataclasses.replace(self.planner, upright_weight=p.upright_weight)
            )
        # the fruit type's prior unless a size or shape was set; the lean's σ is not the type's
        set_lean = dataclasses.replace(FruitPrior(), tilt_sigma_deg=self.fruit.tilt_sigma_deg)
        if world == "mujoco" and self.fruit == set_lean:
            typed = FruitPrior.for_scene(self.scene)
            out = dataclasses.replace(
                out, fruit=dataclasses.replace(typed, tilt_sigma_deg=set_lean.tilt_sigma_deg)
            )
        return out

    @property
    def estimates_calibration(self) -> bool:
        """Whether the state carries the camera's calibration biases: the radius is in the state
        and the sensor declares a calibration error (a per-episode bias, estimated)."""
        s = self.sensor
        return self.filter.state == "centre_radius" and (
            s.focal_error_rel > 0.0 or s.principal_point_error_px > 0.0
        )

    @property
    def prior_source(self) -> Literal["filter", "views"]:
        """The planner's Σo source with ``auto`` resolved."""
        src = self.planner.prior_source
        if src == "auto":
            return "views" if self.planner.planning_model == "paper" else "filter"
        return src

    @property
    def cone_fov_rad(self) -> float:
        c = self.constraints.cone_fov_rad
        return self.camera.hfov_rad if c is None else c

    # The world-dependent numbers as components read them: set, or resolved by for_world; in
    # settings no world resolved, the synthetic world's (the paper's), as measurement.kind =
    # "auto" reads as the range measurement there.

    @property
    def band_distance_m(self) -> float:
        """``constraints.band_distance_m`` (l_dist, eq. 20) [m]."""
        return _or_paper(self.constraints.band_distance_m, "band_distance_m")

    @property
    def band_tolerance_m(self) -> float:
        """``constraints.band_tolerance_m`` (epsilon, eq. 20) [m]."""
        return _or_paper(self.constraints.band_tolerance_m, "band_tolerance_m")

    @property
    def step_m(self) -> float:
        """``constraints.step_m`` (r_d, eq. 21) [m]."""
        return _or_paper(self.constraints.step_m, "step_m")

    @property
    def reference_range_m(self) -> float:
        """``measurement.reference_range_m``, where Σc is taken [m]."""
        v = self.measurement.reference_range_m
        if v is not None:
            return float(v)
        preset = PRESETS["synthetic"].reference_range_m
        return self.band_distance_m if preset is None else preset


def _or_paper(value: float | None, name: str) -> float:
    """``value``, or the synthetic world's (the paper's) preset of ``name`` when unset."""
    return float(getattr(PRESETS["synthetic"], name)) if value is None else float(value)


SECTIONS: dict[str, type] = {
    "camera": CameraConfig,
    "fruit": FruitPrior,
    "measurement": MeasurementConfig,
    "filter": FilterConfig,
    "constraints": ConstraintConfig,
    "planner": PlannerConfig,
    "protocol": ProtocolConfig,
    "robot": RobotConfig,
    "scene": SceneConfig,
    "sensor": SensorConfig,
    "detector": DetectorConfig,
    "episode": EpisodeConfig,
    "faults": FaultConfig,
    "tracking": TrackingConfig,
}


def _suggest(name: str, options: list[str]) -> str:
    close = difflib.get_close_matches(name, options, n=1)
    return f" (did you mean {close[0]!r}?)" if close else ""


def _section_from_dict(section: str, cls: type, data: Any) -> Any:
    if not isinstance(data, Mapping):
        raise ConfigError(section, data, "a table of settings")
    names = [f.name for f in dataclasses.fields(cls)]
    for key in data:
        if key not in names:
            raise ConfigError(
                f"{section}.{key}",
                data[key],
                "one of " + ", ".join(names) + _suggest(str(key), names),
            )
    return cls(**dict(data))


def settings_from_dict(data: Mapping[str, Any], base: Settings | None = None) -> Settings:
    """Build :class:`Settings` from nested mappings (as TOML gives), over ``base``'s values.

    Unknown sections or keys raise :class:`ConfigError` with a "did you mean" suggestion; a
    moved key (:data:`MOVED_KEYS`) is read under its new name with a
    :class:`SettingMovedWarning`.
    """
    return _from_dict(data, base, stacklevel=3)


def _from_dict(data: Mapping[str, Any], base: Settings | None, stacklevel: int) -> Settings:
    base = base or Settings()
    if not isinstance(data, Mapping):
        raise ConfigError("settings", data, "a table of sections")
    data, renamed, notes = move_keys(data)
    sections: dict[str, Any] = {}
    for key, value in data.items():
        if key not in SECTIONS:
            names = list(SECTIONS)
            raise ConfigError(str(key), value, "one of " + ", ".join(names) + _suggest(str(key), names))
        merged = (
            {**dataclasses.asdict(getattr(base, key)), **dict(value)} if isinstance(value, Mapping) else value
        )
        try:
            sections[key] = _section_from_dict(str(key), SECTIONS[key], merged)
        except ConfigError as exc:
            if exc.field in renamed:  # name the key the file gave
                raise ConfigError(f"{renamed[exc.field]} (now {exc.field})", exc.value, exc.allowed) from None
            raise
    out = dataclasses.replace(base, **sections)
    for note in notes:  # once the settings are valid: a bad value is one line, its error
        warnings.warn(note, SettingMovedWarning, stacklevel=stacklevel)
    return out


def load_settings(path: str | Path, base: Settings | None = None) -> Settings:
    """Read :class:`Settings` from a TOML file; missing keys keep ``base``'s values."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError("config", str(p), f"a readable TOML file ({exc.strerror})") from None
    except UnicodeDecodeError as exc:
        raise ConfigError(
            "config", str(p), f"a UTF-8 text TOML file (byte {exc.start} is not UTF-8)"
        ) from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError("config", str(p), f"valid TOML ({exc})") from None
    return _from_dict(data, base, stacklevel=3)


def settings_to_dict(settings: Settings) -> dict[str, Any]:
    """Plain nested dict of every setting plus the derived Σc (JSON-serialisable)."""
    out: dict[str, Any] = dataclasses.asdict(settings)
    out["derived"] = {
        "sigma_c_m2": settings.sigma_c_m2().tolist(),
        "focal_px": settings.camera.focal_px,
        "cone_fov_rad": settings.cone_fov_rad,
        "prior_source": settings.prior_source,
    }
    return out


def _walk(obj: Any, prefix: str) -> Iterator[tuple[str, Any, dataclasses.Field[Any]]]:
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        if dataclasses.is_dataclass(value):
            yield from _walk(value, f"{prefix}{f.name}.")
        else:
            yield f"{prefix}{f.name}", value, f


def describe(settings: Settings) -> list[str]:
    """One line per setting: name = value [unit]  # why. Then the derived Σc."""
    lines = []
    for name, value, f in _walk(settings, ""):
        unit = f.metadata.get("unit", "")
        shown = f"{value:.6g}" if isinstance(value, float) else repr(value)
        lines.append(f"{name} = {shown}{' [' + unit + ']' if unit else ''}  # {f.metadata.get('why', '')}")
    sc = np.sqrt(np.diag(settings.sigma_c_m2()))
    lines.append(
        f"derived Sigma_c std (depth, lateral, lateral) = "
        f"({sc[0] * 1e3:.1f}, {sc[1] * 1e3:.2f}, {sc[2] * 1e3:.2f}) mm at "
        f"{settings.reference_range_m:g} m; focal = {settings.camera.focal_px:.1f} px"
    )
    return lines


def with_overrides(settings: Settings, **sections: dict[str, object]) -> Settings:
    """A copy of ``settings`` with some fields of some sections replaced (validated); a moved
    key (:data:`MOVED_KEYS`) is read under its new name with a :class:`SettingMovedWarning`."""
    moved, _, notes = move_keys(sections)
    changes = {
        name: dataclasses.replace(getattr(settings, name), **values)
        for name, values in moved.items()
        if values
    }
    out = dataclasses.replace(settings, **changes)
    for note in notes:
        warnings.warn(note, SettingMovedWarning, stacklevel=2)
    return out
