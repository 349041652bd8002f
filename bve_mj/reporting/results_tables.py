"""The tables of ``docs/results.md``: the paper's table beside ours, baselines,
recoverability, and the scenario suite."""

from __future__ import annotations

import itertools
import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from bve_mj.atomic import write_json_atomic
from bve_mj.campaigns.scenarios import load_suite, run_suite, suite_json
from bve_mj.campaigns.spec import Cell
from bve_mj.config.experiments import EXPERIMENTS, PAPER_RESULTS
from bve_mj.errors import ConfigError

__all__ = ["PageOptions", "Summaries"]


@dataclass(frozen=True)
class PageOptions:
    """How much to run for the page (defaults: the paper's 100 runs; 20 MuJoCo episodes a
    cell; the paper's recoverability grid, 0-0.5 m in 1 cm steps, 10 runs a point)."""

    runs: int = 100
    mujoco_runs: int = 20
    recover_runs: int = 10
    recover_grid: tuple[float, ...] = tuple(round(0.01 * i, 2) for i in range(51))
    experiments: tuple[str, ...] = tuple(EXPERIMENTS)
    seed: int = 0
    scenario_seeds: int = 20

    def __post_init__(self) -> None:
        for name in ("runs", "mujoco_runs", "recover_runs", "seed", "scenario_seeds"):
            v = getattr(self, name)
            lo = 0 if name == "seed" else 1
            if isinstance(v, bool) or not isinstance(v, int) or v < lo:
                raise ConfigError(name.replace("_", "-"), v, f"an integer >= {lo}")
        if len(self.recover_grid) < 2:
            raise ConfigError("recover-grid", self.recover_grid, "at least two initial errors")

    def command(self) -> str:
        g = self.recover_grid
        step = round(g[1] - g[0], 9)
        uniform = all(abs((b - a) - step) < 1e-9 for a, b in itertools.pairwise(g))
        grid = f"{g[0]:g}:{g[-1]:g}:{step:g}" if uniform else ",".join(f"{e:g}" for e in g)
        return (
            f"bve-mj results --runs {self.runs} --mujoco-runs {self.mujoco_runs} "
            f"--recover-runs {self.recover_runs} --recover-grid {grid} --seed {self.seed} "
            f"--scenario-seeds {self.scenario_seeds}"
            + (
                ""
                if self.experiments == tuple(EXPERIMENTS)
                else f" --experiments {','.join(self.experiments)}"
            )
        )


Summaries = dict[Cell, dict[str, Any]]


def _fmt(x: Any, spec: str = ".1f") -> str:
    return "–" if x is None or (isinstance(x, float) and not np.isfinite(x)) else format(x, spec)


def _find(summ: Summaries, **want: Any) -> dict[str, Any]:
    for c, s in summ.items():
        if all(getattr(c, k) == v for k, v in want.items()):
            return s
    return {}


def _paper_table(syn: Summaries, muj: Summaries, o: PageOptions) -> list[str]:
    lines = [
        "| exp | loss: constraints | paper MAE | paper RMSE | range MAE | range RMSE | range eucl. mean "
        "| range NEES | camera eucl. mean | camera NEES | MuJoCo eucl. mean | MuJoCo p95 | MuJoCo views |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name in o.experiments:
        p = PAPER_RESULTS[name]
        r = _find(syn, experiment=name, planner="bve", measurement="range")
        c = _find(syn, experiment=name, planner="bve", measurement="camera")
        m = _find(muj, experiment=name, planner="bve")
        lines.append(
            f"| {name} | {EXPERIMENTS[name].describe()} | {p['mae_mm']:.1f} | {p['rmse_mm']:.1f} "
            f"| {_fmt(r.get('mae_mm'))} | {_fmt(r.get('rmse_mm'))} | {_fmt(r.get('euclid_mean_mm'))} "
            f"| {_fmt(r.get('nees_mean'), '.2f')} | {_fmt(c.get('euclid_mean_mm'), '.2f')} "
            f"| {_fmt(c.get('nees_mean'), '.2f')} | {_fmt(m.get('euclid_mean_mm'), '.2f')} "
            f"| {_fmt(m.get('euclid_p95_mm'), '.2f')} | {_fmt(m.get('views_median'), '.0f')} |"
        )
    return lines


def _baseline_table(summ: Summaries, world: str, measurement: str, o: PageOptions) -> list[str]:
    baselines = ("random", "circle", "fixed")
    lines = [
        "| exp | BVE | " + " | ".join(baselines) + " | BVE best? |",
        "|---|---|" + "---|" * len(baselines) + "---|",
    ]
    wins = 0
    digits = ".1f" if measurement == "range" else ".2f"
    for name in o.experiments:
        vals = {
            p: _find(summ, experiment=name, planner=p, measurement=measurement).get("euclid_mean_mm")
            for p in ("bve", *baselines)
        }
        b, *others = (np.inf if v is None else float(v) for v in vals.values())
        best = bool(np.isfinite(b) and b <= min(others))
        wins += best
        cells = " | ".join(_fmt(vals[p], digits) for p in ("bve", *baselines))
        lines.append(f"| {name} | {cells} | {'yes' if best else 'no'} |")
    lines.append(
        f"\nBVE has the lowest mean error in {wins} of {len(o.experiments)} experiments "
        f"({world}, {measurement})."
    )
    return lines


def _recover_table(summ: Summaries, factor: float = 2.0) -> list[str]:
    """Median final error at a few initial errors, and the breakdown point: the largest e0
    up to which the median final error stays within ``factor`` x its value at the smallest e0."""
    groups: dict[tuple[str, bool], list[tuple[float, dict[str, Any]]]] = {}
    for c, s in summ.items():
        groups.setdefault((c.experiment, c.approach), []).append((c.initial_error_m, s))
    lines = [
        "| exp | mode | median final error at e0 = 0 / 0.1 / 0.2 / 0.3 / 0.5 m [mm] "
        f"| recovers up to e0 (median ≤ {factor:g}x its value at the smallest e0) |",
        "|---|---|---|---|",
    ]
    for (exp, approach), pts in groups.items():
        pts.sort(key=lambda t: t[0])

        def at(e: float, pts: list[tuple[float, dict[str, Any]]] = pts) -> str:
            near = min(pts, key=lambda t: abs(t[0] - e))
            return _fmt(near[1].get("euclid_median_mm")) if abs(near[0] - e) < 1e-6 else "–"

        base = pts[0][1].get("euclid_median_mm", np.inf)
        limit = None
        for e, s in pts:
            if s.get("euclid_median_mm", np.inf) > factor * base:
                break
            limit = e
        lines.append(
            f"| {exp} | {'approach (eq. 13 on)' if approach else 'localise'} "
            f"| {' / '.join(at(e) for e in (0.0, 0.1, 0.2, 0.3, 0.5))} "
            f"| {'–' if limit is None else f'{limit:g} m'} |"
        )
    return lines


def _scenario_suite(
    work: Path,
    o: PageOptions,
    measurement: str,
    workers: int | None,
    log: Callable[[str], None],
    progress: Callable[[int, int], None] | None,
) -> dict[str, Any]:
    """The suite's ``--json`` document for ``measurement``, reused from ``work`` when it was
    made with the same seeds and scenarios (like the campaigns, a rerun after a code change
    needs a fresh ``--work``)."""
    suite = load_suite()
    path = work / f"scenarios_{measurement}.json"
    if path.exists():
        doc: dict[str, Any] = json.loads(path.read_text(encoding="utf-8"))
        if (doc.get("seeds"), doc.get("seed"), sorted(doc.get("scenarios", {}))) == (
            o.scenario_seeds,
            o.seed,
            sorted(sc.name for sc in suite),
        ):
            log(f"scenarios {measurement}: reused {path}")
            return doc
    log(f"scenarios {measurement}: {len(suite)} x {o.scenario_seeds} episodes -> {path}")
    result = run_suite(
        suite, seeds=o.scenario_seeds, seed=o.seed, measurement=measurement,  # type: ignore[arg-type]
        workers=workers, progress=progress,
    )  # fmt: skip
    doc = suite_json(result)
    work.mkdir(parents=True, exist_ok=True)
    write_json_atomic(path, doc)
    return doc
