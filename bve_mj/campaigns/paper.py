"""The paper's table: Monte-Carlo runs of E1-E10 in the synthetic world, reduced to its metrics
(run i seeded as :mod:`bve_mj.loop.synthetic` says)."""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from bve_mj.campaigns.executors import Task, chunks, local_batches, run_task
from bve_mj.campaigns.runs import run_cell
from bve_mj.campaigns.spec import CampaignSpec
from bve_mj.config import Settings, settings_to_dict
from bve_mj.config.experiments import PAPER_RESULTS, Experiment
from bve_mj.errors import BveError, ConfigError
from bve_mj.estimation.metrics import consistency_metrics, euclidean_metrics, paper_metrics
from bve_mj.loop.synthetic import for_robot

__all__ = ["ExperimentSummary", "run_synthetic", "run_table", "summarise", "table_json"]


def run_synthetic(settings: Settings, experiment: Experiment, seed: int, run: int) -> dict[str, Any]:
    """Run ``run`` of ``experiment`` in the synthetic world with the settings' planner and
    measurement: the campaign's row (:func:`bve_mj.campaigns.runs.run_cell`)."""
    (cell,) = CampaignSpec(experiments=(experiment.name,), planners=(settings.planner.kind,)).cells(settings)
    return run_cell(for_robot(settings), cell, seed, run)


@dataclass(frozen=True)
class ExperimentSummary:
    """An experiment's metrics over its runs (JSON-ready via :meth:`as_dict`)."""

    name: str
    description: str
    runs: int
    metrics: dict[str, float]

    def as_dict(self) -> dict[str, object]:
        return {"description": self.description, "runs": self.runs, **self.metrics}


def summarise(experiment: Experiment, rows: Sequence[dict[str, Any]]) -> ExperimentSummary:
    """Paper metrics, Euclidean errors, consistency, timing and feasibility counts of an
    experiment's campaign rows."""
    truth = np.array([r["truth_m"] for r in rows])
    est = np.array([r["estimate_m"] for r in rows])
    cov = np.array([r["cov_m2"] for r in rows])
    plan_ms = np.concatenate([r["plan_ms"] for r in rows]) if rows else np.zeros(0)
    steps = sum(len(r["plan_ms"]) for r in rows)
    metrics = {
        **paper_metrics(truth, est),
        **euclidean_metrics(truth, est),
        **consistency_metrics(truth, est, cov),
        "plan_ms_median": float(np.median(plan_ms)) if plan_ms.size else float("nan"),
        "restoring_steps_pct": 100.0 * sum(r["restoring_steps"] for r in rows) / max(steps, 1),
        "best_feasible_steps_pct": 100.0 * sum(r["best_feasible_steps"] for r in rows) / max(steps, 1),
        "runs_never_feasible": float(sum(not r["ever_feasible"] for r in rows)),
    }
    return ExperimentSummary(experiment.name, experiment.describe(), len(rows), metrics)


def run_table(
    settings: Settings,
    experiments: Sequence[Experiment],
    runs: int,
    seed: int,
    workers: int | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> dict[str, ExperimentSummary]:
    """Every experiment × ``runs`` runs: a synthetic campaign in memory (its cells, its run
    function and its executors: the same rows as ``bve-mj campaign``), reduced to the table.

    Raises:
        BveError: naming the first run that crashed or failed (the table would be wrong).
    """
    if isinstance(runs, bool) or not isinstance(runs, int) or runs < 1:
        raise ConfigError("runs", runs, "an integer >= 1")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ConfigError("seed", seed, "an integer >= 0")
    workers = workers or os.cpu_count() or 1
    if workers < 1:
        raise ConfigError("workers", workers, "an integer >= 1")
    settings = for_robot(settings)
    spec = CampaignSpec(experiments=tuple(e.name for e in experiments), planners=(settings.planner.kind,))
    items = [(cell, run) for cell in spec.cells(settings) for run in range(runs)]
    tasks: list[Task] = [(settings, chunk, seed) for chunk in chunks(items, workers)]
    rows: dict[str, list[dict[str, Any]]] = {e.name: [] for e in experiments}
    done, total = 0, len(items)
    for batch in local_batches(run_task, tasks, min(workers, len(tasks))):
        for row in batch:
            if row["outcome"] in ("crashed", "failed"):
                raise BveError(f"{row['key']}: {row['outcome']}: {row.get('message', '')}")
            rows[row["experiment"]].append(row)
        done += len(batch)
        if progress:
            progress(done, total)
    return {e.name: summarise(e, sorted(rows[e.name], key=lambda r: r["run"])) for e in experiments}


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
