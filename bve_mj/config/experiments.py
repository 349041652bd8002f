"""The paper's experiments E1-E10 (a loss and a set of constraints each) and its Table 1."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from bve_mj.config.fields import ConstraintName, LossName
from bve_mj.errors import ConfigError

__all__ = ["EXPERIMENTS", "PAPER_RESULTS", "Experiment", "parse_experiments"]


@dataclass(frozen=True)
class Experiment:
    """One of the paper's experiments: a loss and a set of constraints."""

    name: str
    loss: LossName
    constraints: tuple[ConstraintName, ...]
    needs_arm: bool = False

    def describe(self) -> str:
        extra = " + arm kinematics" if self.needs_arm else ""
        return f"{self.loss}: {' + '.join(self.constraints)}{extra}"


def _pair(
    n: int, constraints: tuple[ConstraintName, ...], arm: bool = False
) -> tuple[Experiment, Experiment]:
    return (
        Experiment(f"E{n}", "dispersion", constraints, arm),
        Experiment(f"E{n + 5}", "max_eigenvalue", constraints, arm),
    )


_E3: tuple[ConstraintName, ...] = ("workspace", "outside_fruit", "cone")


_ALL = [
    *_pair(1, ("band",)),
    *_pair(2, ("band", "workspace")),
    *_pair(3, _E3),
    *_pair(4, (*_E3, "wall")),
    *_pair(5, (*_E3, "wall"), arm=True),
]


EXPERIMENTS: dict[str, Experiment] = {e.name: e for e in sorted(_ALL, key=lambda e: int(e.name[1:]))}

"""E1-E5: dispersion loss; E6-E10: max-eigenvalue loss, with E1-E5's constraints."""


PAPER_RESULTS: dict[str, dict[str, float]] = {
    name: dict(zip(("mape_pct", "mae_mm", "rmse_mm", "mse_mm2"), row, strict=True))
    for name, row in {
        "E1": (5.12, 37.1, 15.5, 241.64),
        "E2": (12.86, 52.5, 25.5, 650.47),
        "E3": (8.64, 53.8, 28.1, 790.79),
        "E4": (11.65, 57.2, 29.1, 848.40),
        "E5": (10.62, 60.9, 31.2, 971.44),
        "E6": (32.38, 53.5, 26.3, 689.63),
        "E7": (14.79, 53.1, 24.7, 612.17),
        "E8": (12.62, 48.0, 21.2, 447.57),
        "E9": (10.44, 53.0, 23.4, 548.17),
        "E10": (20.06, 62.3, 31.3, 982.65),
    }.items()
}

"""The paper's Table 1 (per-axis metrics as printed; its MAE > RMSE cannot come from its
own eqs. 34-37)."""


def parse_experiments(text: str | Iterable[str]) -> list[Experiment]:
    """Experiments from "E1,E3" or a list of names; raises ConfigError naming the unknown."""
    names = [n.strip() for n in (text.split(",") if isinstance(text, str) else text) if n.strip()]
    if not names:
        raise ConfigError("experiments", text, "a comma-separated list of " + ",".join(EXPERIMENTS))
    out = []
    for n in names:
        key = n.upper()
        if key not in EXPERIMENTS:
            raise ConfigError("experiments", n, "names from " + ",".join(EXPERIMENTS))
        out.append(EXPERIMENTS[key])
    return out
