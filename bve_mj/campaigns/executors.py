"""Where runs execute: in this process, in a pool of spawned processes, or on a Dask cluster."""

from __future__ import annotations

import contextlib
import ctypes
import multiprocessing
import os
import signal
import sys
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from typing import Any, TypeVar

from bve_mj.campaigns.runs import _failed_row, run_cell
from bve_mj.campaigns.spec import Cell
from bve_mj.config import Settings
from bve_mj.config.experiments import EXPERIMENTS
from bve_mj.errors import ConfigError

__all__ = ["Task", "chunks", "local_batches", "run_task"]

_PR_SET_PDEATHSIG = 1  # prctl(2): the signal a process gets when its parent dies

# --------------------------------------------------------------------------- execution
Task = tuple[Settings, tuple[tuple[Cell, int], ...], int]


T = TypeVar("T")


def run_task(task: Task) -> list[dict[str, Any]]:
    """Run a chunk; a run that crashes (a bug, not bad input) becomes a "crashed" row so
    that one bad run never takes down the other thousands (stored, retried on resume)."""
    from bve_mj.threads import one_blas_thread

    settings, items, seed = task
    rows = []
    # one BLAS thread: the same result in-process, in a local pool and on a Dask worker
    with one_blas_thread():
        for cell, run in items:
            try:
                rows.append(run_cell(settings, cell, seed, run))
            except Exception as exc:
                rows.append(_failed_row(cell, seed, run, "crashed", f"{type(exc).__name__}: {exc}"))
    return rows


def local_batches(
    run: Callable[[T], list[dict[str, Any]]], tasks: Sequence[T], workers: int
) -> Iterator[list[dict[str, Any]]]:
    """``run(task)`` for every task, in this process (``workers`` = 1) or in a pool of
    spawned processes, yielding each task's rows as it finishes."""
    if workers == 1:
        yield from map(run, tasks)
        return
    # spawn, not fork: a forked child inherits the parent's EGL/OpenGL state and can deadlock
    pool = ProcessPoolExecutor(
        max_workers=workers,
        mp_context=multiprocessing.get_context("spawn"),
        initializer=_die_with_parent,
        initargs=(os.getpid(),),
    )
    try:
        pending: set[Future[list[dict[str, Any]]]] = {pool.submit(run, t) for t in tasks}
        while pending:
            finished, pending = wait(pending, return_when=FIRST_COMPLETED)
            for fut in finished:
                yield fut.result()
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def _die_with_parent(parent_pid: int) -> None:
    """A pool worker ends when the process that started it dies (Linux: SIGTERM on the
    parent's death), so a run killed outright (SIGTERM or SIGKILL, which no ``finally`` sees)
    leaves no orphans rendering on to the end of their chunk."""
    if sys.platform.startswith("linux"):
        with contextlib.suppress(OSError, AttributeError):  # no prctl: it ends when its chunk does
            ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)
    if os.getppid() != parent_pid:  # the parent died before the watch was set
        os._exit(1)


def _dask_batches(tasks: list[Task], scheduler: str) -> Iterator[list[dict[str, Any]]]:
    try:
        from distributed import Client, as_completed
    except ImportError:
        raise ConfigError(
            "scheduler", scheduler, "a Dask scheduler with dask installed: pip install 'bve_mj[dask]'"
        ) from None
    try:
        client = Client(scheduler, timeout="5s")
    except (OSError, TimeoutError, ValueError) as exc:
        allowed = f"the address of a running Dask scheduler ({exc})"
        raise ConfigError("scheduler", scheduler, allowed) from None
    try:
        futures = client.map(run_task, tasks, pure=False)
        for fut in as_completed(futures):
            yield fut.result()
    finally:
        client.close()


def _with_arm(cell: Cell) -> bool:
    """A synthetic cell whose planner solves the arm's kinematics (E5, E10): ~7x the time of
    the others' runs."""
    experiment = EXPERIMENTS.get(cell.experiment)
    return experiment is not None and experiment.needs_arm


def chunks(items: list[tuple[Cell, int]], workers: int) -> list[tuple[tuple[Cell, int], ...]]:
    """The runs in tasks, longest first: the MuJoCo runs one run index a task (run ``i`` of
    every cell is the same scene, built once by the worker that runs them:
    :data:`bve_mj.loop.start.KEPT_SCENES`), then chunks of the synthetic runs with the arm,
    then of the others, so that the pool's last tasks are short and no worker idles long at
    the end. (Every run is seeded on its own and rows are keyed: the order changes no result.)"""
    mujoco: dict[int, list[tuple[Cell, int]]] = {}
    for it in items:
        if it[0].world == "mujoco":
            mujoco.setdefault(it[1], []).append(it)
    synthetic = [it for it in items if it[0].world != "mujoco"]
    size = max(1, min(10, len(synthetic) // max(1, 4 * workers)))
    out: list[tuple[tuple[Cell, int], ...]] = [tuple(runs) for runs in mujoco.values()]
    for part in (
        [it for it in synthetic if _with_arm(it[0])],
        [it for it in synthetic if not _with_arm(it[0])],
    ):
        out += [tuple(part[i : i + size]) for i in range(0, len(part), size)]
    return out
