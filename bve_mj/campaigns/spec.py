"""What a campaign runs: its cells (experiment × world × planner × measurement × initial error
× mode), their settings, and each run's seed."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, get_args

import numpy as np

from bve_mj.config import MeasurementKind, PlannerKind, Settings, WorldName, with_overrides
from bve_mj.config.experiments import EXPERIMENTS
from bve_mj.errors import ConfigError

__all__ = [
    "MEASUREMENTS",
    "PLANNERS",
    "WORLDS",
    "CampaignSpec",
    "Cell",
    "cell_settings",
    "episode_seed",
    "parse_grid",
]

WORLDS: tuple[str, ...] = get_args(WorldName)
PLANNERS: tuple[str, ...] = get_args(PlannerKind)
MEASUREMENTS: tuple[str, ...] = tuple(k for k in get_args(MeasurementKind) if k != "auto")


@dataclass(frozen=True, order=True)
class Cell:
    """One combination of the campaign's axes; its runs are the Monte-Carlo samples."""

    world: str
    experiment: str
    planner: str
    measurement: str
    initial_error_m: float
    approach: bool = False

    @property
    def label(self) -> str:
        mode = " approach" if self.approach else ""
        return (
            f"{self.world} {self.experiment} {self.planner} {self.measurement} "
            f"e0={self.initial_error_m:g} m{mode}"
        )

    def key(self, run: int) -> str:
        """The run's identity in the store (stable across sessions and machines)."""
        return (
            f"{self.world}/{self.experiment}/{self.planner}/{self.measurement}/"
            f"{self.initial_error_m:.6g}/{'approach' if self.approach else 'localise'}/{run}"
        )


def _names(field_name: str, values: Any, allowed: Sequence[str]) -> tuple[str, ...]:
    items = values.split(",") if isinstance(values, str) else values
    try:
        out = tuple(str(v).strip() for v in items if str(v).strip())
    except TypeError:
        raise ConfigError(field_name, values, "a list of " + ", ".join(allowed)) from None
    bad = [v for v in out if v not in allowed]
    if not out or bad:
        raise ConfigError(field_name, bad[0] if bad else values, "a list of " + ", ".join(allowed))
    return tuple(dict.fromkeys(out))


def parse_grid(text: str) -> tuple[float, ...]:
    """Initial errors [m] from ``"0.1"``, ``"0.05,0.1,0.2"`` or ``"START:STOP:STEP"`` (STOP
    included), e.g. the paper's sweep ``"0:0.5:0.01"`` (51 values)."""
    allowed = "metres >= 0 as X, X,Y,... or START:STOP:STEP (e.g. 0:0.5:0.01)"
    try:
        if ":" in text:
            start, stop, step = (float(x) for x in text.split(":"))
            if not (step > 0 and stop >= start) or not all(map(math.isfinite, (start, stop, step))):
                raise ValueError
            n = math.floor((stop - start) / step + 1e-9) + 1
            if n > 10_000:
                raise ValueError
            values = tuple(round(start + i * step, 9) for i in range(n))
        else:
            values = tuple(float(x) for x in text.split(",") if x.strip())
    except ValueError:
        raise ConfigError("initial_errors", text, allowed) from None
    if not values or any(not math.isfinite(v) or v < 0 for v in values):
        raise ConfigError("initial_errors", text, allowed)
    return values


@dataclass(frozen=True)
class CampaignSpec:
    """What to run: the product of the axes, ``runs`` seeded runs per cell.

    Empty or None axes take the settings' value for each world, so a settings file is never
    silently overridden: ``measurements`` empty: ``measurement.kind`` (``auto``: range in the
    synthetic world, camera in MuJoCo); ``initial_errors_m`` empty: ``protocol.initial_error_m``
    in the synthetic world, ``episode.initial_error_m`` in MuJoCo; ``approach`` None:
    ``episode.approach``. ``approach``: the eq. 13 term on (and, in MuJoCo, approach mode: no
    band, end close to the fruit).
    """

    experiments: tuple[str, ...] = tuple(EXPERIMENTS)
    worlds: tuple[str, ...] = ("synthetic",)
    planners: tuple[str, ...] = ("bve",)
    measurements: tuple[str, ...] = ()
    initial_errors_m: tuple[float, ...] = ()
    runs: int = 100
    seed: int = 0
    approach: bool | None = None
    recovered_mm: float = field(default=30.0, metadata={"why": "a run 'recovered' below this final error"})

    def __post_init__(self) -> None:
        exps = _names("experiments", self.experiments, [e.upper() for e in EXPERIMENTS])
        object.__setattr__(self, "experiments", exps)
        object.__setattr__(self, "worlds", _names("worlds", self.worlds, WORLDS))
        object.__setattr__(self, "planners", _names("planners", self.planners, PLANNERS))
        if self.measurements:
            object.__setattr__(self, "measurements", _names("measurements", self.measurements, MEASUREMENTS))
        else:
            object.__setattr__(self, "measurements", ())
        errs = self.initial_errors_m
        if isinstance(errs, str) or not all(
            isinstance(e, (int, float)) and not isinstance(e, bool) and math.isfinite(e) and e >= 0
            for e in errs
        ):
            raise ConfigError("initial_errors", errs, "a list of metres >= 0")
        object.__setattr__(self, "initial_errors_m", tuple(float(e) for e in errs))
        for name, value, lo in (("runs", self.runs, 1), ("seed", self.seed, 0)):
            if isinstance(value, bool) or not isinstance(value, int) or value < lo:
                raise ConfigError(name, value, f"an integer >= {lo}")
        if self.approach is not None and not isinstance(self.approach, bool):
            raise ConfigError("approach", self.approach, "true, false or none (the settings' value)")
        r = self.recovered_mm
        if isinstance(r, bool) or not isinstance(r, (int, float)) or not (math.isfinite(r) and r > 0):
            raise ConfigError("recovered_mm", r, "a number of millimetres > 0")

    def cells(self, settings: Settings) -> list[Cell]:
        """Every cell, in a fixed order (world, experiment, planner, measurement, error)."""
        out = []
        approach = settings.episode.approach if self.approach is None else self.approach
        for world in self.worlds:
            synthetic = world == "synthetic"
            default = settings.protocol.initial_error_m if synthetic else settings.episode.initial_error_m
            measurements = self.measurements or (settings.for_world(world).measurement.kind,)  # type: ignore[arg-type]
            for exp in self.experiments:
                for planner in self.planners:
                    for meas in measurements:
                        for e in self.initial_errors_m or (default,):
                            out.append(Cell(world, exp, planner, meas, e, approach))
        return out

    def as_dict(self) -> dict[str, Any]:
        return {
            "experiments": list(self.experiments),
            "worlds": list(self.worlds),
            "planners": list(self.planners),
            "measurements": list(self.measurements),
            "initial_errors_m": list(self.initial_errors_m),
            "runs": self.runs,
            "seed": self.seed,
            "approach": self.approach,
            "recovered_mm": self.recovered_mm,
        }


def cell_settings(settings: Settings, cell: Cell) -> Settings:
    """``settings`` with the cell's planner, measurement, initial error and mode applied."""
    planner: dict[str, object] = {"kind": cell.planner}
    if cell.approach and cell.world == "synthetic" and settings.planner.approach_aggressiveness == 0.0:
        planner["approach_aggressiveness"] = 1.0
    if cell.world == "synthetic":
        return with_overrides(
            settings,
            planner=planner,
            measurement={"kind": cell.measurement},
            protocol={"initial_error_m": cell.initial_error_m},
        )
    return with_overrides(
        settings,
        planner=planner,
        measurement={"kind": cell.measurement},
        episode={
            "experiment": cell.experiment,
            "initial_error_m": cell.initial_error_m,
            "approach": cell.approach,
        },
    )


def episode_seed(seed: int, run: int) -> int:
    """The ``bve-mj episode --seed`` of MuJoCo run ``run`` of a campaign seeded ``seed``."""
    return int(np.random.SeedSequence(seed, spawn_key=(run,)).generate_state(1)[0])
