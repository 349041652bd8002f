"""All sections together: :class:`Settings`, loading from TOML (unknown names get a "did you
mean"), and :func:`describe`."""

from __future__ import annotations

import dataclasses
import difflib
import math
import sys
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, get_args

import numpy as np

from bve_mj.config.episode import DetectorConfig, EpisodeConfig, FaultConfig
from bve_mj.config.fields import MeasurementKind, StateKind, WorldName
from bve_mj.config.planning import ConstraintConfig, PlannerConfig, ProtocolConfig, RobotConfig
from bve_mj.config.scene import SceneConfig, SensorConfig
from bve_mj.config.sensing import CameraConfig, FilterConfig, FruitPrior, MeasurementConfig
from bve_mj.errors import ConfigError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

__all__ = [
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
    """Every setting of a synthetic (paper-protocol) run."""

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

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            expected = SECTIONS[f.name]
            if not isinstance(value, expected):
                raise ConfigError(f.name, value, f"a {expected.__name__}")

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
        rho = m.reference_range_m
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

        - ``measurement.kind = "auto"`` becomes ``range`` in the synthetic world (the paper's
          EKF) and ``camera`` in MuJoCo;
        - ``filter.state = "auto"`` becomes ``centre`` in the synthetic world (the paper's
          state) and ``centre_radius`` in MuJoCo (the fruit's radius estimated with it);
        - in MuJoCo, a ``fruit`` section left at its defaults (the paper's r_k = 35 mm ±15%)
          becomes the prior of the scene's fruit type (:meth:`FruitPrior.for_scene`): the
          estimator knows the variety it is picking, not each fruit's size. Any value set in
          ``[fruit]`` keeps the whole section as given.
        """
        if world not in get_args(WorldName):
            raise ConfigError("world", world, "one of " + ", ".join(get_args(WorldName)))
        out = self
        if self.measurement.kind == "auto":
            kind: MeasurementKind = "range" if world == "synthetic" else "camera"
            out = dataclasses.replace(out, measurement=dataclasses.replace(out.measurement, kind=kind))
        if world == "synthetic" and self.filter.state == "centre_radius":
            raise ConfigError(
                "filter.state",
                self.filter.state,
                "auto or centre in the synthetic world (it measures the centre, not an image: "
                "centre_radius needs the MuJoCo world)",
            )
        if self.filter.state == "auto":
            state: StateKind = "centre" if world == "synthetic" else "centre_radius"
            out = dataclasses.replace(out, filter=dataclasses.replace(out.filter, state=state))
        if world == "mujoco" and self.fruit == FruitPrior():
            out = dataclasses.replace(out, fruit=FruitPrior.for_scene(self.scene))
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

    Unknown sections or keys raise :class:`ConfigError` with a "did you mean" suggestion.
    """
    base = base or Settings()
    if not isinstance(data, Mapping):
        raise ConfigError("settings", data, "a table of sections")
    sections: dict[str, Any] = {}
    for key, value in data.items():
        if key not in SECTIONS:
            names = list(SECTIONS)
            raise ConfigError(str(key), value, "one of " + ", ".join(names) + _suggest(str(key), names))
        merged = (
            {**dataclasses.asdict(getattr(base, key)), **dict(value)} if isinstance(value, Mapping) else value
        )
        sections[key] = _section_from_dict(str(key), SECTIONS[key], merged)
    return dataclasses.replace(base, **sections)


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
    return settings_from_dict(data, base)


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
        f"{settings.measurement.reference_range_m:g} m; focal = {settings.camera.focal_px:.1f} px"
    )
    return lines


def with_overrides(settings: Settings, **sections: dict[str, object]) -> Settings:
    """A copy of ``settings`` with some fields of some sections replaced (validated)."""
    changes = {
        name: dataclasses.replace(getattr(settings, name), **values)
        for name, values in sections.items()
        if values
    }
    return dataclasses.replace(settings, **changes)
