"""The scenario suite: named greenhouse scenes run over seeds, the table users judge us by.

A scenario is a TOML file of settings (sections of :class:`bve_mj.config.Settings`) in the
suite's folder, ``examples/scenarios/suite/`` in a checkout (installed as data beside the
models otherwise); its name is the file's stem and its first comment lines describe it.
Every scenario runs ``seeds`` MuJoCo episodes, episode ``i`` seeded
:func:`bve_mj.campaigns.spec.episode_seed` ``(seed, i)`` (``bve-mj episode --config FILE --seed
<it>`` replays it), spread over spawned worker processes.

Per scenario: outcome counts, final error median / p95 / max, mean NEES, the share of truths
inside the final 3σ ellipsoid, and **silent failures**: episodes that claim success
(``converged``, ``stable``, ``approached``) while the truth lies outside their final claim's
99.9% region (its bound's ellipsoid, :mod:`bve_mj.estimation.claim_shape`): confident wrong
answers, the number that must be zero. Beside it, **exit0 out** (``answered_outside``) counts
the same for every outcome that exits 0 (``stalled`` and ``max_views`` too: they give an
estimate, though they do not claim it is done).
"""

from __future__ import annotations

import math
import os
import sysconfig
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from bve_mj.campaigns.executors import local_batches
from bve_mj.campaigns.runs import radius_metrics
from bve_mj.campaigns.spec import episode_seed
from bve_mj.campaigns.suite_table import format_suite
from bve_mj.config import FilterKind, MeasurementKind, Settings, StateKind, load_settings, settings_to_dict
from bve_mj.errors import BveError, ConfigError
from bve_mj.estimation.claim_shape import share_within
from bve_mj.estimation.metrics import consistency_curve, nees_band
from bve_mj.loop.records import since_reset

__all__ = [
    "SILENT_NEES",
    "SILENT_PROBABILITY",
    "Scenario",
    "SuiteResult",
    "crashed_rows",
    "format_suite",
    "load_suite",
    "run_chunk",
    "run_rows",
    "run_suite",
    "suite_dir",
    "suite_json",
    "suite_json_clean",
]

"""Outcomes that claim the fruit is localised."""
SILENT_PROBABILITY, SILENT_NEES = 0.999, 16.266
"""A success outside its claim's region at this probability is a silent failure (χ²₃'s: Gaussian)."""


@dataclass(frozen=True)
class Scenario:
    """A named scene: its settings file and what it is for."""

    name: str
    path: Path
    description: str

    def settings(
        self,
        measurement: MeasurementKind | None = None,
        filter_kind: FilterKind | None = None,
        state: StateKind | None = None,
    ) -> Settings:
        """The file's settings for the closed loop (each argument given overrides the file's
        ``measurement.kind``, ``filter.kind``, ``filter.state``)."""
        from bve_mj.config import with_overrides

        s = load_settings(self.path)
        given: dict[str, object] = {
            k: v for k, v in (("kind", filter_kind), ("state", state)) if v is not None
        }
        s = with_overrides(
            s, measurement={"kind": measurement} if measurement is not None else {}, filter=given
        )
        return s.for_world("mujoco")


def suite_dir() -> Path:
    """The suite's folder: ``examples/scenarios/suite`` beside the package in a checkout, or
    the installed data (``share/bve_mj/scenarios``)."""
    here = Path(__file__).resolve().parents[2] / "examples" / "scenarios" / "suite"
    for c in (here, Path(sysconfig.get_path("data")) / "share" / "bve_mj" / "scenarios"):
        if c.is_dir() and any(c.glob("*.toml")):
            return c
    raise ConfigError("scenarios", str(here), "the scenario suite folder (reinstall bve_mj)")


def _description(path: Path) -> str:
    lines = []
    for line in path.read_text(encoding="utf-8").splitlines():
        if not line.startswith("#"):
            break
        lines.append(line.lstrip("# ").strip())
    return " ".join(x for x in lines if x)


def load_suite(directory: str | Path | None = None, only: Sequence[str] | None = None) -> list[Scenario]:
    """The scenarios of ``directory`` (default :func:`suite_dir`), sorted by name, or those
    named in ``only`` in that order; every file is loaded once here, so a bad one is a
    :class:`ConfigError` before anything runs."""
    folder = Path(directory) if directory is not None else suite_dir()
    if not folder.is_dir():
        raise ConfigError("scenarios", str(folder), "a folder of scenario TOML files")
    found = {p.stem: p for p in sorted(folder.glob("*.toml"))}
    if not found:
        raise ConfigError("scenarios", str(folder), "a folder holding scenario TOML files")
    names = list(found) if not only else [n.strip() for n in only if n.strip()]
    unknown = [n for n in names if n not in found]
    if unknown or not names:
        raise ConfigError("only", ",".join(unknown) or only, "names from " + ",".join(found))
    suite = [Scenario(n, found[n], _description(found[n])) for n in dict.fromkeys(names)]
    for sc in suite:
        load_settings(sc.path)  # validates; raises ConfigError naming the field
    return suite


# --------------------------------------------------------------------------- running
Task = tuple[str, tuple[Settings, ...], int, tuple[int, ...]]
"""(scenario, its settings variants, base seed, runs): each run with each variant in turn."""


def _run_one(name: str, settings: Settings, seed: int, run: int) -> dict[str, Any]:
    from bve_mj.loop.mujoco import run_mujoco_episode

    ep_seed = episode_seed(seed, run)
    try:
        ep = run_mujoco_episode(settings, ep_seed)
    except BveError as exc:
        return {
            "scenario": name,
            "run": run,
            "episode_seed": ep_seed,
            "outcome": "failed",
            "message": str(exc),
        }
    final, shape, outcome = ep.result.final_claim, ep.result.shape, ep.result.outcome
    d, nees = final.centre_m - ep.truth, final.mahalanobis_sq(ep.truth)
    silent_nees = shape.region(SILENT_PROBABILITY)
    return {
        "scenario": name,
        "run": run,
        "episode_seed": ep_seed,
        "outcome": outcome,
        "views": len(ep.result.views),
        "error_mm": 1e3 * float(np.linalg.norm(d)),
        "nees": nees,
        "filter_nees": ep.result.final_filter.mahalanobis_sq(ep.truth),
        "sigma_max_mm": 1e3 * final.sigma_max_m,
        "claim_dof": None if math.isinf(shape.dof) else shape.dof,
        "silent_failure": bool(outcome.success and nees > silent_nees),
        "answered_outside": bool(outcome.localised and nees > silent_nees),
        "disputed": ep.standing_dispute() is not None,
        "detected_views": sum(v.measured for v in ep.result.views),
        "accepted_views": sum(v.accepted for v in ep.result.views),
        "truth_m": ep.truth.tolist(),
        "radius_mm": 1e3 * ep.info.target.radius_m,
        "estimate_m": final.centre_m.tolist(),
        "cramer_rao_mm": ep.cramer_rao_mm(),
        **radius_metrics(final, ep.true_radius_m),
        "claim_features": claim_features(ep.result.views),
        "wall_s": ep.result.wall_s,
    }


def claim_features(views: Sequence[Any]) -> dict[str, float | int | None]:
    """What the loop saw of the fruit in the views its final claim fused (those accepted
    since the last belief reset), for studies of the claim against the truth: the accepted
    views, the mean ``neighbour_share``, ``arc_deg``, ``trimmed_fraction`` and apparent
    ``radius_px`` of their detections, the mean NIS per measured dimension (``nis_per_dof``,
    the correlation between views not discounted) and the share of all views in which the
    detector refused the fruit (``refused_share``). None where no view was accepted."""
    fused: list[Any] = [v for v in since_reset(views) if v.accepted and isinstance(v.world, dict)]
    dets = [v.world.get("detection") or {} for v in fused]
    dets = [d for d in dets if "radius_px" in d]

    def mean(key: str) -> float | None:
        xs = [float(d[key]) for d in dets if d.get(key) is not None]
        return float(np.mean(xs)) if xs else None

    dims = [len(v.world.get("measurement", {}).get("z", ())) or 3 for v in fused]
    nis = sum(float(v.nis) for v in fused if math.isfinite(v.nis))
    return {
        "accepted": len(fused),
        "neighbour_share": mean("neighbour_share"),
        "arc_deg": mean("arc_deg"),
        "trimmed_fraction": mean("trimmed_fraction"),
        "radius_px": mean("radius_px"),
        "nis_per_dof": nis / sum(dims) if fused else None,
        "refused_share": sum(not v.measured for v in views) / len(views) if views else None,
    }


def run_chunk(
    run_one: Callable[[str, Settings, int, int], dict[str, Any]], task: Task
) -> list[dict[str, Any]]:
    """``run_one(name, settings, seed, run)`` for every run of the task with each of its
    settings variants in turn (a run's episodes one after another share its scene: see
    :data:`bve_mj.loop.start.KEPT_SCENES`), each row tagged with its variant's index, with one
    BLAS thread (results identical in any process); an exception is a bug: a ``crashed`` row
    with one line, kept out of the metrics (exit 1)."""
    from bve_mj.threads import one_blas_thread

    name, variants, seed, runs = task
    with one_blas_thread():
        rows = []
        for run in runs:
            for k, settings in enumerate(variants):
                try:
                    row = run_one(name, settings, seed, run)
                except Exception as exc:
                    row = {"scenario": name, "run": run, "outcome": "crashed",
                           "message": f"{type(exc).__name__}: {exc}"}  # fmt: skip
                rows.append({**row, "variant": k})
        return rows


def crashed_rows(rows: dict[str, tuple[dict[str, Any], ...]]) -> list[str]:
    """One line per crashed episode of these scenario rows."""
    return [
        f"{r['scenario']} run {r['run']}: {r['message']}"
        for scenario in rows.values()
        for r in scenario
        if r["outcome"] == "crashed"
    ]


@dataclass(frozen=True)
class SuiteResult:
    """Every scenario's episode rows (in run order) and the settings each ran with."""

    scenarios: tuple[Scenario, ...]
    settings: dict[str, Settings]
    rows: dict[str, tuple[dict[str, Any], ...]]
    seed: int
    seeds: int
    wall_s: float

    def summary(self, name: str) -> dict[str, Any]:
        rows = self.rows[name]
        ok = [r for r in rows if r["outcome"] not in ("failed", "crashed")]
        outcomes: dict[str, int] = {}
        for r in rows:
            outcomes[r["outcome"]] = outcomes.get(r["outcome"], 0) + 1
        err = np.array([r["error_mm"] for r in ok]) if ok else np.array([math.nan])
        nees = np.array([r["nees"] for r in ok]) if ok else np.array([math.nan])
        dofs = [r.get("claim_dof") for r in ok]  # each claim's shape (None: Gaussian)
        filter_nees = np.array([r.get("filter_nees", math.nan) for r in ok]) if ok else np.array([math.nan])
        r_err = np.array([abs(r["radius_error_mm"]) for r in ok if r.get("radius_error_mm") is not None])
        r_nees = np.array([r["radius_nees"] for r in ok if r.get("radius_nees") is not None])
        r_dofs = [r.get("claim_dof") for r in ok if r.get("radius_nees") is not None]
        crb = np.array(
            [r["error_mm"] / r["cramer_rao_mm"] for r in ok if np.isfinite(r.get("cramer_rao_mm", math.nan))]
        )
        return {
            "description": next(s.description for s in self.scenarios if s.name == name),
            "outcomes": outcomes,
            "error_mm": {
                "median": float(np.median(err)),
                "p95": float(np.percentile(err, 95)),
                "max": float(np.max(err)),
            },
            "nees_mean": float(np.mean(nees)),
            "filter_nees_mean": float(np.mean(filter_nees)),
            "nees_band_95": nees_band(len(ok)) if ok else (math.nan, math.nan),
            "claim_nees_band_95": nees_band(len(ok), tail_dofs=dofs) if ok else (math.nan, math.nan),
            "inside_3sigma_pct": float(np.mean(nees <= 9.0) * 100.0) if ok else math.nan,
            "inside_3sigma_honest_pct": float(np.mean([100 * share_within(d, 9) for d in dofs] or math.nan)),
            "consistency": consistency_curve(nees, tail_dofs=dofs) if ok else [],
            "radius_error_mm": {
                "median": float(np.median(r_err)) if r_err.size else math.nan,
                "p95": float(np.percentile(r_err, 95)) if r_err.size else math.nan,
            },
            "radius_nees_mean": float(np.mean(r_nees)) if r_nees.size else math.nan,
            "radius_nees_band_95": (
                nees_band(r_nees.size, 1, tail_dofs=r_dofs) if r_nees.size else (math.nan, math.nan)
            ),
            "error_to_crb_median": float(np.median(crb)) if crb.size else math.nan,
            "silent_failures": sum(bool(r.get("silent_failure")) for r in rows),
            "answered_outside": sum(bool(r.get("answered_outside")) for r in rows),
            "disputed": sum(bool(r.get("disputed")) for r in rows),  # a dispute standing at the end
            "views_median": float(np.median([r["views"] for r in ok])) if ok else math.nan,
            "wall_s": float(sum(r.get("wall_s", 0.0) for r in rows)),
            "runs": list(rows),
        }

    @property
    def crashed(self) -> list[str]:
        return crashed_rows(self.rows)


def run_suite(
    scenarios: Sequence[Scenario],
    *,
    seeds: int = 20,
    seed: int = 0,
    measurement: MeasurementKind | None = None,
    filter_kind: FilterKind | None = None,
    state: StateKind | None = None,
    workers: int | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> SuiteResult:
    """Run ``seeds`` episodes of every scenario (``measurement``, ``filter_kind`` and
    ``state`` override each file's)."""
    for name, value, lo in (("seeds", seeds, 1), ("seed", seed, 0)):
        if isinstance(value, bool) or not isinstance(value, int) or value < lo:
            raise ConfigError(name, value, f"an integer >= {lo}")
    workers = (os.cpu_count() or 1) if workers is None else workers
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ConfigError("workers", workers, "an integer >= 1")
    if measurement is not None and measurement not in ("camera", "range"):
        raise ConfigError("measurement", measurement, "camera or range")
    t0 = time.perf_counter()
    settings = {sc.name: sc.settings(measurement, filter_kind, state) for sc in scenarios}
    variants: dict[str, tuple[Settings, ...]] = {name: (s,) for name, s in settings.items()}
    (rows,) = run_rows(partial(run_chunk, _run_one), scenarios, variants, seed, seeds, workers, progress)
    return SuiteResult(tuple(scenarios), settings, rows, seed, seeds, time.perf_counter() - t0)


def run_rows(
    run_task: Callable[[Task], list[dict[str, Any]]],
    scenarios: Sequence[Scenario],
    variants: dict[str, tuple[Settings, ...]],
    seed: int,
    seeds: int,
    workers: int,
    progress: Callable[[int, int], None] | None,
) -> list[dict[str, tuple[dict[str, Any], ...]]]:
    """Every scenario's ``seeds`` episodes with each of its settings ``variants`` (as many for
    every scenario), in chunks of runs over ``workers`` spawned processes (``run_task`` runs
    one chunk, every variant of a run in turn): per variant, each scenario's rows in run order."""
    chunk = max(1, min(5, seeds // max(1, 2 * workers)))
    tasks: list[Task] = [
        (sc.name, variants[sc.name], seed, tuple(range(start, min(seeds, start + chunk))))
        for sc in scenarios
        for start in range(0, seeds, chunk)
    ]
    n = len(variants[scenarios[0].name]) if scenarios else 1
    collected: list[dict[str, list[dict[str, Any]]]] = [{sc.name: [] for sc in scenarios} for _ in range(n)]
    total, done = len(scenarios) * seeds * n, 0
    if progress is not None:
        progress(0, total)
    for batch in local_batches(run_task, tasks, min(workers, len(tasks))):
        for row in batch:
            collected[row.pop("variant")][row["scenario"]].append(row)
        done += len(batch)
        if progress is not None:
            progress(done, total)
    return [{name: tuple(sorted(r, key=lambda x: x["run"])) for name, r in c.items()} for c in collected]


def suite_json_clean(x: Any) -> Any:
    """``x`` with every non-finite float replaced by None (JSON has no NaN)."""
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, dict):
        return {k: suite_json_clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [suite_json_clean(v) for v in x]
    return x


def suite_json(result: SuiteResult) -> dict[str, Any]:
    """The ``--json`` document: per scenario under ``scenarios.<name>``, and the settings."""
    return suite_json_clean(
        {
            "seed": result.seed,
            "seeds": result.seeds,
            "wall_s": result.wall_s,
            "scenarios": {sc.name: result.summary(sc.name) for sc in result.scenarios},
            "settings": {n: settings_to_dict(s) for n, s in result.settings.items()},
        }
    )
