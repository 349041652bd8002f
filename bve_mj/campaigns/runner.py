"""Seeded Monte-Carlo campaigns: experiment × world × planner × measurement × initial error × run.

A campaign lives in a directory:

- ``runs.sqlite``: one row per finished run, committed as each run comes back (SQLite
  transactions are atomic: a campaign killed half way loses only the runs in flight, and
  the database is never left torn). The base settings and seed are stored with it; a
  campaign resumed in the same directory skips every run already there and refuses
  other settings (their runs would not be comparable).
- ``runs.csv``, ``summary.json`` and the plots, written atomically from the database
  when the campaign ends (``bve_mj.reporting.campaign_report``).

Seeding: run ``i`` of every cell uses the same draws (:func:`bve_mj.loop.synthetic.synthetic_episode`
in the synthetic world; ``bve-mj episode --seed S`` with ``S`` = :func:`episode_seed` in the
MuJoCo world), so cells are paired and results do not depend on how runs are spread over
processes or machines."""

from __future__ import annotations

import functools
import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bve_mj.campaigns.executors import Task, _dask_batches, chunks, local_batches, run_task
from bve_mj.campaigns.spec import CampaignSpec, Cell
from bve_mj.campaigns.store import STORE_FORMAT, RunStore, code_identity
from bve_mj.config import Settings, settings_to_dict
from bve_mj.errors import ConfigError
from bve_mj.loop.synthetic import for_robot

__all__ = ["CampaignResult", "run_campaign"]


@dataclass(frozen=True)
class CampaignResult:
    """A finished (or resumed and finished) campaign: its rows in cell order."""

    spec: CampaignSpec
    settings: Settings
    cells: tuple[Cell, ...]
    rows: tuple[dict[str, Any], ...]
    resumed_runs: int
    computed_runs: int
    crashed: tuple[str, ...]
    wall_s: float
    directory: Path
    code_change: str | None = None

    @functools.cached_property
    def _by_key(self) -> dict[str, dict[str, Any]]:
        return {r["key"]: r for r in self.rows}

    def cell_rows(self, cell: Cell) -> list[dict[str, Any]]:
        """The cell's finished runs, in run order."""
        by_key = self._by_key
        return [by_key[k] for k in (cell.key(r) for r in range(self.spec.runs)) if k in by_key]


def run_campaign(
    settings: Settings,
    spec: CampaignSpec,
    directory: str | Path,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    progress: Callable[[int, int], None] | None = None,
    strict: bool = False,
) -> CampaignResult:
    """Run every cell × run of ``spec`` not yet in ``directory``'s store; return all rows.

    The store records the code that started it (:func:`code_identity`); resuming under other
    code is noted in the result's ``code_change``, or refused with ``strict``.

    ``workers``: local processes (default: all cores); ``scheduler``: a Dask distributed
    scheduler address instead (``tcp://host:8786``; dask imported only then).
    """
    if not isinstance(spec, CampaignSpec):
        raise ConfigError("spec", spec, "a CampaignSpec")
    out = Path(directory)
    if out.exists() and not out.is_dir():
        raise ConfigError("out", str(out), "a directory (a file is there)")
    workers = os.cpu_count() or 1 if workers is None else workers
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ConfigError("workers", workers, "an integer >= 1")
    if scheduler is not None and (not isinstance(scheduler, str) or not scheduler.strip()):
        raise ConfigError("scheduler", scheduler, "a Dask scheduler address such as tcp://127.0.0.1:8786")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigError("out", str(out), f"a directory that can be created ({exc.strerror})") from None
    if not os.access(out, os.W_OK | os.X_OK):
        raise ConfigError("out", str(out), "a writable directory")
    settings = for_robot(settings)
    cells = spec.cells(settings)
    t0 = time.perf_counter()
    identity = {"format": STORE_FORMAT, "seed": spec.seed, "settings": settings_to_dict(settings)}
    store = RunStore(out, identity, code_identity(), strict)
    crashed: list[str] = []
    try:
        done = store.done()
        todo = [(c, r) for c in cells for r in range(spec.runs) if c.key(r) not in done]
        total = len(cells) * spec.runs
        resumed = total - len(todo)
        if progress is not None:
            progress(resumed, total)
        tasks: list[Task] = [(settings, chunk, spec.seed) for chunk in chunks(todo, workers)]
        batches = _dask_batches(tasks, scheduler) if scheduler else local_batches(run_task, tasks, workers)
        finished = resumed
        for batch in batches:
            store.add(batch)
            crashed.extend(f"{r['key']}: {r['message']}" for r in batch if r["outcome"] == "crashed")
            finished += len(batch)
            if progress is not None:
                progress(finished, total)
        rows = store.rows(c.key(r) for c in cells for r in range(spec.runs))
    finally:
        store.close()
    return CampaignResult(
        spec, settings, tuple(cells), tuple(rows), resumed, len(todo), tuple(crashed),
        time.perf_counter() - t0, out, store.code_change,
    )  # fmt: skip
