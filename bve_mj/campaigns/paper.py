"""The paper's table: Monte-Carlo runs of E1-E10 in the synthetic world, reduced to its metrics
(run i seeded as :mod:`bve_mj.loop.synthetic` says)."""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass

import numpy as np

from bve_mj.config import Settings, settings_to_dict
from bve_mj.config.experiments import PAPER_RESULTS, Experiment
from bve_mj.errors import ConfigError
from bve_mj.estimation.metrics import consistency_metrics, euclidean_metrics, paper_metrics
from bve_mj.loop.synthetic import for_robot, synthetic_episode


@dataclass(frozen=True)
class RunRecord:
    """The outcome of one synthetic run (all that the tables need)."""

    experiment: str
    run: int
    truth: np.ndarray
    estimate: np.ndarray
    cov: np.ndarray
    plan_ms: np.ndarray
    restoring_steps: int
    best_feasible_steps: int
    ever_feasible: bool
    wall_s: float


def run_synthetic(settings: Settings, experiment: Experiment, seed: int, run: int) -> RunRecord:
    """Run ``run`` of ``experiment`` in the synthetic world (:func:`synthetic_episode`),
    reduced to what the tables need."""
    scenario, result = synthetic_episode(settings, experiment, seed, run)
    planned = result.views[1:]
    return RunRecord(
        experiment=experiment.name,
        run=run,
        truth=scenario.p_world_fruit,
        estimate=np.array(result.final.centre_m),
        cov=np.array(result.final.position.cov),
        plan_ms=np.array([v.plan_s * 1e3 for v in planned]),
        restoring_steps=sum(v.plan_status == "restoring" for v in planned),
        best_feasible_steps=sum(v.plan_status == "best_feasible" for v in planned),
        ever_feasible=any(v.plan_feasible for v in planned),
        wall_s=result.wall_s,
    )


@dataclass(frozen=True)
class ExperimentSummary:
    """An experiment's metrics over its runs (JSON-ready via :meth:`as_dict`)."""

    name: str
    description: str
    runs: int
    metrics: dict[str, float]

    def as_dict(self) -> dict[str, object]:
        return {"description": self.description, "runs": self.runs, **self.metrics}


def summarise(experiment: Experiment, records: Sequence[RunRecord]) -> ExperimentSummary:
    """Paper metrics, Euclidean errors, consistency, timing and feasibility counts."""
    truth = np.array([r.truth for r in records])
    est = np.array([r.estimate for r in records])
    cov = np.array([r.cov for r in records])
    plan_ms = np.concatenate([r.plan_ms for r in records]) if records else np.zeros(0)
    steps = sum(len(r.plan_ms) for r in records)
    metrics = {
        **paper_metrics(truth, est),
        **euclidean_metrics(truth, est),
        **consistency_metrics(truth, est, cov),
        "plan_ms_median": float(np.median(plan_ms)) if plan_ms.size else float("nan"),
        "restoring_steps_pct": 100.0 * sum(r.restoring_steps for r in records) / max(steps, 1),
        "best_feasible_steps_pct": 100.0 * sum(r.best_feasible_steps for r in records) / max(steps, 1),
        "runs_never_feasible": float(sum(not r.ever_feasible for r in records)),
    }
    return ExperimentSummary(experiment.name, experiment.describe(), len(records), metrics)


def _run_chunk(args: tuple[Settings, Experiment, int, Sequence[int]]) -> list[RunRecord]:
    settings, experiment, seed, runs = args
    return [run_synthetic(settings, experiment, seed, r) for r in runs]


def run_table(
    settings: Settings,
    experiments: Sequence[Experiment],
    runs: int,
    seed: int,
    workers: int | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> dict[str, ExperimentSummary]:
    """Every experiment × ``runs`` runs, spread over ``workers`` processes."""
    if isinstance(runs, bool) or not isinstance(runs, int) or runs < 1:
        raise ConfigError("runs", runs, "an integer >= 1")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ConfigError("seed", seed, "an integer >= 0")
    workers = workers or os.cpu_count() or 1
    if workers < 1:
        raise ConfigError("workers", workers, "an integer >= 1")
    settings = for_robot(settings)
    runnable = list(experiments)
    chunk = max(1, min(25, runs // max(1, 2 * workers)))
    tasks = [
        (settings, e, seed, list(range(start, min(runs, start + chunk))))
        for e in runnable
        for start in range(0, runs, chunk)
    ]
    total, done = len(runnable) * runs, 0
    records: dict[str, list[RunRecord]] = {e.name: [] for e in runnable}
    if workers == 1 or len(tasks) == 1:
        results: Iterable[list[RunRecord]] = map(_run_chunk, tasks)
        for batch in results:
            done += len(batch)
            records[batch[0].experiment].extend(batch)
            if progress:
                progress(done, total)
    else:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            for batch in pool.map(_run_chunk, tasks):
                done += len(batch)
                records[batch[0].experiment].extend(batch)
                if progress:
                    progress(done, total)
    return {e.name: summarise(e, sorted(records[e.name], key=lambda r: r.run)) for e in experiments}


def table_json(
    settings: Settings,
    summaries: dict[str, ExperimentSummary],
    *,
    seed: int,
    runs: int,
    wall_s: float,
) -> dict[str, object]:
    """The ``--json`` document: settings (with the seed) and the per-experiment metrics."""
    return {
        "settings": {**settings_to_dict(settings), "seed": seed, "runs": runs},
        "experiments": {name: s.as_dict() for name, s in summaries.items()},
        "paper": PAPER_RESULTS,
        "wall_s": wall_s,
        "created_unix_s": time.time(),
    }
