"""Settings of the greenhouse scene (fruit types, the row, trusses, leaves, light) and of the
sensors."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import get_args

from bve_mj.config.fields import (
    FruitType,
    OtherTrussesRipeness,
    RipenessName,
    TrussLayout,
    _choice,
    _int_at_least,
    _non_negative,
    _optional_range,
    _positive,
    _positive_int,
    _range,
    _why,
)
from bve_mj.errors import ConfigError

__all__ = [
    "FRUIT_TYPE_DIAMETER_M",
    "FRUIT_TYPE_PER_TRUSS",
    "FRUIT_TYPE_SHAPE_INDEX",
    "SceneConfig",
    "SensorConfig",
]

FRUIT_TYPE_DIAMETER_M: dict[str, tuple[float, float]] = {
    "cherry": (0.015, 0.030),
    "cocktail": (0.030, 0.045),
    "round": (0.047, 0.067),
    "beefsteak": (0.067, 0.100),
    "plum": (0.035, 0.050),
}

"""Equatorial (horizontal) diameter range of each fruit type [m] (docs/greenhouse.md)."""


FRUIT_TYPE_SHAPE_INDEX: dict[str, tuple[float, float]] = {
    "cherry": (0.90, 1.00),
    "cocktail": (0.85, 1.00),
    "round": (0.80, 0.95),
    "beefsteak": (0.60, 0.80),
    "plum": (1.20, 1.60),
}

"""Shape index (height / width) range of each fruit type (docs/greenhouse.md)."""

FRUIT_TYPE_PER_TRUSS: dict[str, tuple[int, int]] = {
    "cherry": (12, 25),
    "cocktail": (8, 14),
    "round": (4, 8),
    "beefsteak": (2, 5),
    "plum": (4, 8),
}

"""Fruit per truss of each type, inclusive (docs/greenhouse.md; beefsteak, which it does not
give: 2-5): the range configurations are drawn in (:mod:`bve_mj.campaigns.drawn_scenes`)."""


@dataclass(frozen=True, kw_only=True)
class SceneConfig:
    """The greenhouse scene: the arm on a pedestal before a high-wire tomato row (robot base
    frame). Plants, trusses, fruit, leaves and light are drawn from the scene's seed within
    these settings; ``bve_mj.sim.scene`` documents the model."""

    pedestal_height_m: float = field(
        default=0.75,
        metadata=_why("robot base above the floor: puts trusses at 0.0-0.45 m within reach", "m"),
    )
    row_x_m: float = field(default=0.50, metadata=_why("stem line of the plant row in front of the arm", "m"))
    plants: int = field(default=5, metadata=_why("stems along the row, 0.3-0.5 m apart"))
    target_x_m: tuple[float, float] = field(
        default=(0.40, 0.45), metadata=_why("ripe target centre x: on the robot side of the row", "m")
    )
    target_y_m: tuple[float, float] = field(default=(-0.20, 0.20), metadata=_why("target centre y", "m"))
    target_z_m: tuple[float, float] = field(default=(0.05, 0.40), metadata=_why("target centre z", "m"))
    fruit_type: FruitType = field(
        default="round",
        metadata=_why(
            "cherry, cocktail, round, beefsteak or plum: sets the default size and shape-index "
            "ranges (docs/greenhouse.md)"
        ),
    )
    fruit_radius_m: tuple[float, float] | None = field(
        default=None,
        metadata=_why(
            "equatorial radius range of the fruit, each drawn within it; None = from fruit_type "
            "(round: 23.5-33.5 mm)",
            "m",
        ),
    )
    shape_index: tuple[float, float] | None = field(
        default=None,
        metadata=_why(
            "height / width range, each fruit drawn within it (< 1 flattened, > 1 elongated); "
            "None = from fruit_type (round: 0.80-0.95)"
        ),
    )
    trusses: int = field(
        default=3,
        metadata=_why("trusses near the target, one of them the target's, on the plants around it"),
    )
    fruit_per_truss: int = field(
        default=5, metadata=_why("fruit on each truss (round 4-8, cocktail 8-14, cherry 12-25)")
    )
    target_index: int = field(
        default=0,
        metadata=_why("which fruit of its truss is the target, 0 = the one nearest the stem (ripens first)"),
    )
    truss_layout: TrussLayout = field(
        default="chain",
        metadata=_why(
            "chain: fruit one after another along the bending rachis, touching; cluster: fruit "
            "alternating on both sides of it (two rows), touching"
        ),
    )
    ripeness: tuple[RipenessName, ...] = field(
        default=(),
        metadata=_why(
            "ripeness class of each fruit of the target's truss, index 0 nearest the stem "
            "(green, breaker, turning, pink, light_red, red); empty = drawn, ripening from the "
            "stem outward: fruit inward of the target 0-1 classes riper each, the one just outward "
            "3-4 classes less ripe (the target is its truss's ripe one), each further one 0-1 less"
        ),
    )
    target_ripeness: RipenessName = field(
        default="red", metadata=_why("the target's class when ripeness is drawn (ignored when it is given)")
    )
    other_trusses_ripeness: OtherTrussesRipeness = field(
        default="unripe",
        metadata=_why(
            "the other trusses, ripening from the stem outward: unripe = first fruit green, "
            "breaker or turning (no red beside the target); mixed = first fruit of any class"
        ),
    )
    leaf_density: float = field(
        default=1.0,
        metadata=_why(
            "scales the number of compound leaves (1 = one every 5-8 cm of stem above the "
            "stripped ripe zone; 0 = none)"
        ),
    )
    leaves_per_plant: int | None = field(
        default=None,
        metadata=_why(
            "legacy (leaflets per stem in the old scene): when set, scales leaf_density by it / 16"
        ),
    )
    distractors: int | None = field(
        default=None,
        metadata=_why(
            "legacy: when set, this many fruit in all on max(1, trusses - 1) other trusses (0 = only "
            "the target's truss); None = trusses - 1 other trusses of fruit_per_truss fruit each"
        ),
    )
    sun_azimuth_deg: tuple[float, float] = field(
        default=(135.0, 225.0),
        metadata=_why(
            "where the sun is, drawn in this range: 0 = behind the row (+x, backlit fruit), "
            "180 = behind the robot (front lit), 90 = +y",
            "deg",
        ),
    )
    sun_elevation_deg: tuple[float, float] = field(
        default=(40.0, 70.0), metadata=_why("sun above the horizon, drawn in this range", "deg")
    )
    sun_intensity: tuple[float, float] = field(
        default=(0.45, 0.75),
        metadata=_why("diffuse intensity of the sun (direct light), drawn in this range"),
    )
    light_intensity: tuple[float, float] | None = field(
        default=None, metadata=_why("legacy name of sun_intensity: when set, it replaces it")
    )
    sky_intensity: float = field(
        default=0.6,
        metadata=_why("diffuse sky through the glass: uniform ambient plus soft light from above"),
    )
    backlight: float = field(
        default=0.0,
        metadata=_why("intensity of a low light from behind the row towards the camera; 0 = none"),
    )
    shadows: bool = field(
        default=False, metadata=_why("the sun casts hard shadows: several times the render cost on a CPU")
    )
    headlight: bool = field(
        default=False, metadata=_why("a light on the camera (MuJoCo's headlight), like a flash or ring light")
    )

    def __post_init__(self) -> None:
        _positive("scene", "pedestal_height_m", self.pedestal_height_m)
        _positive("scene", "row_x_m", self.row_x_m)
        _positive_int("scene", "plants", self.plants, 50)
        _positive_int("scene", "trusses", self.trusses, 20)
        _positive_int("scene", "fruit_per_truss", self.fruit_per_truss, 40)
        _int_at_least("scene", "target_index", self.target_index, 0)
        if self.target_index >= self.fruit_per_truss:
            raise ConfigError(
                "scene.target_index",
                self.target_index,
                f"an integer < fruit_per_truss = {self.fruit_per_truss}",
            )
        for name in ("leaves_per_plant", "distractors"):
            v = getattr(self, name)
            if v is not None:
                _int_at_least("scene", name, v, 0)
        for name in ("target_x_m", "target_y_m", "target_z_m"):
            object.__setattr__(self, name, _range("scene", name, getattr(self, name)))
        _choice("scene", "fruit_type", self.fruit_type, FruitType)
        _choice("scene", "truss_layout", self.truss_layout, TrussLayout)
        _choice("scene", "target_ripeness", self.target_ripeness, RipenessName)
        _choice("scene", "other_trusses_ripeness", self.other_trusses_ripeness, OtherTrussesRipeness)
        object.__setattr__(
            self,
            "fruit_radius_m",
            _optional_range("scene", "fruit_radius_m", self.fruit_radius_m, 1e-3, 0.15),
        )
        shape = _optional_range("scene", "shape_index", self.shape_index, 0.0, 5.0)
        if shape is not None and shape[0] <= 0.0:
            raise ConfigError("scene.shape_index", self.shape_index, "a pair 0 < low <= high <= 5")
        object.__setattr__(self, "shape_index", shape)
        classes = get_args(RipenessName)
        given = self.ripeness
        if isinstance(given, (str, bytes, Mapping)) or not isinstance(given, (list, tuple)):
            raise ConfigError(
                "scene.ripeness", given, "a list of ripeness classes (" + ", ".join(classes) + ")"
            )
        for name in given:
            if name not in classes:
                raise ConfigError("scene.ripeness", list(given), "ripeness classes: " + ", ".join(classes))
        if given and len(given) != self.fruit_per_truss:
            raise ConfigError(
                "scene.ripeness", list(given), f"{self.fruit_per_truss} classes (fruit_per_truss), or none"
            )
        object.__setattr__(self, "ripeness", tuple(given))
        _non_negative("scene", "leaf_density", self.leaf_density)
        object.__setattr__(
            self, "sun_azimuth_deg", _range("scene", "sun_azimuth_deg", self.sun_azimuth_deg, -360.0, 360.0)
        )
        object.__setattr__(
            self, "sun_elevation_deg", _range("scene", "sun_elevation_deg", self.sun_elevation_deg, 0.0, 90.0)
        )
        object.__setattr__(self, "sun_intensity", _range("scene", "sun_intensity", self.sun_intensity, 0.0))
        object.__setattr__(
            self, "light_intensity", _optional_range("scene", "light_intensity", self.light_intensity, 0.0)
        )
        _non_negative("scene", "sky_intensity", self.sky_intensity)
        _non_negative("scene", "backlight", self.backlight)
        for name in ("shadows", "headlight"):
            if not isinstance(getattr(self, name), bool):
                raise ConfigError(f"scene.{name}", getattr(self, name), "true or false")
        if self.target_x_m[1] >= self.row_x_m:
            raise ConfigError("scene.target_x_m", self.target_x_m, f"values below row_x_m = {self.row_x_m}")

    @property
    def radius_range_m(self) -> tuple[float, float]:
        """Equatorial fruit radius range [m]: ``fruit_radius_m``, else half ``fruit_type``'s diameters."""
        if self.fruit_radius_m is not None:
            return self.fruit_radius_m
        lo, hi = FRUIT_TYPE_DIAMETER_M[self.fruit_type]
        return (lo / 2.0, hi / 2.0)

    @property
    def shape_index_range(self) -> tuple[float, float]:
        """Height / width range: ``shape_index``, else ``fruit_type``'s."""
        return self.shape_index if self.shape_index is not None else FRUIT_TYPE_SHAPE_INDEX[self.fruit_type]

    @property
    def sun_intensity_range(self) -> tuple[float, float]:
        """The sun's intensity range: ``light_intensity`` (legacy) when set, else ``sun_intensity``."""
        return self.light_intensity if self.light_intensity is not None else self.sun_intensity

    @property
    def leaf_scale(self) -> float:
        """``leaf_density``, times ``leaves_per_plant / 16`` when the legacy setting is given."""
        legacy = 1.0 if self.leaves_per_plant is None else self.leaves_per_plant / 16.0
        return self.leaf_density * legacy


@dataclass(frozen=True, kw_only=True)
class SensorConfig:
    """Sensor realism, seeded: off (ideal) by default, on in the ``realistic`` preset."""

    image_noise_std: float = field(default=0.0, metadata=_why("Gaussian pixel noise, 8-bit levels"))
    focal_error_rel: float = field(
        default=0.0, metadata=_why("std of the relative error of the focal length the detector assumes")
    )
    principal_point_error_px: float = field(
        default=0.0, metadata=_why("std of the principal-point error the detector assumes", "px")
    )
    encoder_noise_rad: float = field(default=0.0, metadata=_why("joint encoder noise std", "rad"))

    def __post_init__(self) -> None:
        for f in ("image_noise_std", "focal_error_rel", "principal_point_error_px", "encoder_noise_rad"):
            _non_negative("sensor", f, getattr(self, f))

    @classmethod
    def realistic(cls) -> SensorConfig:
        """OAK-1-like: 2 levels of noise, 1% focal and 2 px principal-point calibration error,
        Dynamixel Pro encoder resolution (~0.0004 rad at 501,923 counts/turn) as noise."""
        return cls(
            image_noise_std=2.0, focal_error_rel=0.01, principal_point_error_px=2.0, encoder_noise_rad=4e-4
        )
