"""Seeded Monte-Carlo campaigns: experiment × world × planner × measurement × initial error × run.

A campaign lives in a directory:

- ``runs.sqlite``: one row per finished run, committed as each run comes back (SQLite
  transactions are atomic: a campaign killed half way loses only the runs in flight, and
  the database is never left torn). The base settings and seed are stored with it; a
  campaign resumed in the same directory skips every run already there and refuses
  other settings (their runs would not be comparable).
- ``runs.csv``, ``summary.json`` and the plots, written atomically from the database
  when the campaign ends (``bve_mj.campaign_report``).

Seeding: run ``i`` of every cell uses the same draws (:func:`bve_mj.experiments.synthetic_episode`
in the synthetic world; ``bve-mj episode --seed S`` with ``S`` = :func:`episode_seed` in the
MuJoCo world), so cells are paired and results do not depend on how runs are spread over
processes or machines.
"""

from __future__ import annotations

import functools
import json
import math
import multiprocessing
import os
import sqlite3
import subprocess
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, TypeVar, get_args

import numpy as np

from bve_mj.config import Settings, settings_to_dict
from bve_mj.episode import EpisodeResult
from bve_mj.errors import BveError, ConfigError
from bve_mj.estimation.belief import Belief
from bve_mj.experiments import EXPERIMENTS, for_robot, synthetic_episode, with_overrides
from bve_mj.robot import arm_kinematics

__all__ = [
    "WORLDS",
    "CampaignResult",
    "CampaignSpec",
    "Cell",
    "RunStore",
    "cell_settings",
    "episode_seed",
    "local_batches",
    "parse_grid",
    "run_campaign",
    "run_cell",
]

WorldName = Literal["synthetic", "mujoco"]
WORLDS: tuple[str, ...] = get_args(WorldName)
PLANNERS = ("bve", "random", "circle")
MEASUREMENTS = ("range", "camera")
STORE_FORMAT = 1


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


def _row(
    cell: Cell,
    run: int,
    seed: int,
    truth: np.ndarray,
    result: EpisodeResult,
    ep_seed: int | None,
    joint_violation_rad: float = 0.0,
    true_radius_m: float | None = None,
) -> dict[str, Any]:
    final = result.final.position
    d = final.mean - truth
    planned = result.views[1:]
    errors = [float(np.linalg.norm(v.belief.centre_m - truth)) * 1e3 for v in result.views]
    finite = all(
        np.all(np.isfinite(v.belief.mean)) and np.all(np.isfinite(v.belief.cov)) for v in result.views
    )
    return {
        "key": cell.key(run),
        "world": cell.world,
        "experiment": cell.experiment,
        "planner": cell.planner,
        "measurement": cell.measurement,
        "initial_error_m": cell.initial_error_m,
        "approach": cell.approach,
        "run": run,
        "seed": seed,
        "episode_seed": ep_seed,
        "outcome": result.outcome,
        "views": len(result.views),
        "error_mm": float(np.linalg.norm(d)) * 1e3,
        "error_xyz_mm": (d * 1e3).tolist(),
        "nees": float(d @ np.linalg.solve(final.cov, d)),
        "sigma_max_mm": float(np.sqrt(np.linalg.eigvalsh(final.cov)[-1])) * 1e3,
        "plan_ms_median": float(np.median([v.plan_s for v in planned])) * 1e3 if planned else 0.0,
        "restoring_steps": sum(v.plan_status == "restoring" for v in planned),
        "fallback_steps": sum(v.plan_status == "fallback" for v in planned),
        "events": result.event_counts(),
        "belief_finite": bool(finite),
        "joint_limit_violation_rad": joint_violation_rad,
        "min_camera_fruit_distance_m": min(
            (float(np.linalg.norm(v.p_world_camera - truth)) for v in result.views), default=float("nan")
        ),
        "detected_views": sum(v.measured for v in result.views),
        "accepted_views": sum(v.accepted for v in result.views),
        "wall_s": result.wall_s,
        "truth_m": truth.tolist(),
        "estimate_m": final.mean.tolist(),
        "cov_m2": final.cov.tolist(),
        "prior_m": result.prior.centre_m.tolist(),
        "error_by_view_mm": errors,
        "camera_path_m": [v.p_world_camera.tolist() for v in result.views],
        "estimate_path_m": [v.belief.centre_m.tolist() for v in result.views],
        **radius_metrics(result.final, true_radius_m),
    }


def radius_metrics(final: Belief, true_radius_m: float | None) -> dict[str, float | None]:
    """The final radius estimate, its σ, its error [mm] and NEES (None where the state holds
    no radius or the truth is unknown)."""
    r, sd = final.radius_m, final.radius_sigma_m
    if r is None or sd is None or true_radius_m is None:
        return {"radius_mm": r and 1e3 * r, "radius_sigma_mm": sd and 1e3 * sd, "radius_error_mm": None,
                "radius_nees": None}  # fmt: skip
    err = r - true_radius_m
    return {"radius_mm": 1e3 * r, "radius_sigma_mm": 1e3 * sd, "radius_error_mm": 1e3 * err,
            "radius_nees": (err / sd) ** 2}  # fmt: skip


def run_cell(settings: Settings, cell: Cell, seed: int, run: int) -> dict[str, Any]:
    """Run ``run`` of ``cell`` and return its JSON-ready row.

    A run that fails on purpose (a :class:`BveError`: no reachable start pose, say) is a
    row with outcome ``"failed"`` and the message; its errors are NaN.
    """
    s = cell_settings(settings, cell)
    try:
        if cell.world == "synthetic":
            scenario, result = synthetic_episode(s, EXPERIMENTS[cell.experiment], seed, run)
            return _row(cell, run, seed, scenario.p_world_fruit, result, None)
        from bve_mj.mujoco_episode import run_mujoco_episode

        ep_seed = episode_seed(seed, run)
        episode = run_mujoco_episode(s, ep_seed)
        kin = arm_kinematics(s.robot.name, s.robot.limit_set)
        violation = 0.0
        for v in episode.result.views:
            q = (v.world or {}).get("q_rad")
            if q is not None:
                qa = np.asarray(q)
                below, above = kin.limits.lower - qa, qa - kin.limits.upper
                violation = max(violation, float(np.max(np.maximum(below, above))))
        return _row(
            cell,
            run,
            seed,
            episode.truth,
            episode.result,
            ep_seed,
            max(violation, 0.0),
            episode.true_radius_m,
        )
    except BveError as exc:
        return _failed_row(cell, seed, run, "failed", str(exc))


def _failed_row(cell: Cell, seed: int, run: int, outcome: str, message: str) -> dict[str, Any]:
    return {
        "key": cell.key(run), "world": cell.world, "experiment": cell.experiment,
        "planner": cell.planner, "measurement": cell.measurement,
        "initial_error_m": cell.initial_error_m, "approach": cell.approach, "run": run,
        "seed": seed, "episode_seed": episode_seed(seed, run) if cell.world == "mujoco" else None,
        "outcome": outcome, "message": message, "views": 0,
        "error_mm": float("nan"), "nees": float("nan"), "wall_s": 0.0,
    }  # fmt: skip


# --------------------------------------------------------------------------- store
def _first_difference(a: Any, b: Any, path: str = "") -> str | None:
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            d = _first_difference(a.get(k), b.get(k), f"{path}.{k}" if path else k)
            if d:
                return d
        return None
    return None if a == b else f"{path or 'value'}: {a!r} here, {b!r} asked"


def code_identity() -> dict[str, str]:
    """The code that makes a run: the package version and, from a git checkout, its commit
    (``+dirty`` with uncommitted changes to tracked files; ``unknown`` outside a checkout)."""
    from bve_mj import __version__

    here = Path(__file__).resolve().parent
    commit = "unknown"
    try:
        head = subprocess.run(
            ["git", "-C", str(here), "rev-parse", "HEAD"], capture_output=True, text=True, timeout=10
        )
        if head.returncode == 0:
            commit = head.stdout.strip()
            dirty = subprocess.run(
                ["git", "-C", str(here), "status", "--porcelain", "--untracked-files=no"],
                capture_output=True, text=True, timeout=10,
            )  # fmt: skip
            if dirty.returncode == 0 and dirty.stdout.strip():
                commit += "+dirty"
    except (OSError, subprocess.SubprocessError):
        pass
    return {"version": __version__, "commit": commit}


class RunStore:
    """The campaign's SQLite database: finished runs by key, the identity they share, and the
    code that made them (:func:`code_identity`).

    A campaign resumed under other code than the one that started it mixes rows of two
    programs: :attr:`code_change` says so (the CLI prints it); ``strict`` refuses instead."""

    FILENAME = "runs.sqlite"

    def __init__(
        self,
        directory: str | Path,
        identity: dict[str, Any],
        code: dict[str, str] | None = None,
        strict: bool = False,
    ) -> None:
        self.path = Path(directory) / self.FILENAME
        self.code_change: str | None = None
        ident = json.loads(json.dumps(identity))
        try:
            self._db = sqlite3.connect(self.path, timeout=30.0)
            self._db.execute("CREATE TABLE IF NOT EXISTS meta (name TEXT PRIMARY KEY, value TEXT NOT NULL)")
            self._db.execute(
                "CREATE TABLE IF NOT EXISTS runs "
                "(key TEXT PRIMARY KEY, outcome TEXT NOT NULL, row TEXT NOT NULL)"
            )
            found = self._db.execute("SELECT value FROM meta WHERE name = 'identity'").fetchone()
            if found is None:
                with self._db:
                    self._db.execute("INSERT INTO meta VALUES ('identity', ?)", (json.dumps(ident),))
            else:
                diff = _first_difference(json.loads(found[0]), ident)
                if diff is not None:
                    self._db.close()
                    raise ConfigError(
                        "out",
                        str(directory),
                        "a new directory, or the settings and seed of the campaign already in it "
                        f"(they differ at {diff})",
                    )
            if code is not None:
                self._check_code(str(directory), code, strict)
        except sqlite3.DatabaseError as exc:
            raise ConfigError(
                "out", str(directory), f"a campaign directory ({self.path.name} is unreadable: {exc})"
            ) from None

    def _check_code(self, directory: str, code: dict[str, str], strict: bool) -> None:
        found = self._db.execute("SELECT value FROM meta WHERE name = 'code'").fetchone()
        if found is None:
            with self._db:
                self._db.execute("INSERT INTO meta VALUES ('code', ?)", (json.dumps(code),))
            return
        made = json.loads(found[0])
        if made == code:
            return
        change = (
            f"its runs were made by bve_mj {made.get('version')} at commit {made.get('commit')}; "
            f"this is {code['version']} at {code['commit']}"
        )
        if strict:
            self._db.close()
            raise ConfigError("out", directory, f"a campaign made by this code (--strict: {change})")
        self.code_change = change

    def done(self) -> set[str]:
        """Keys of the finished runs (a crashed run is not finished: it is run again)."""
        return {k for (k,) in self._db.execute("SELECT key FROM runs WHERE outcome != 'crashed'")}

    def add(self, rows: Iterable[dict[str, Any]]) -> None:
        """Store rows in one transaction (all or none)."""
        with self._db:
            self._db.executemany(
                "INSERT OR REPLACE INTO runs VALUES (?, ?, ?)",
                [(r["key"], r["outcome"], json.dumps(r)) for r in rows],
            )

    def rows(self, keys: Iterable[str]) -> list[dict[str, Any]]:
        """The stored rows of ``keys`` that are done, in the order given."""
        wanted = list(keys)
        found = {k: json.loads(r) for k, r in self._db.execute("SELECT key, row FROM runs")}
        return [found[k] for k in wanted if k in found]

    def close(self) -> None:
        self._db.close()


# --------------------------------------------------------------------------- execution
Task = tuple[Settings, tuple[tuple[Cell, int], ...], int]
T = TypeVar("T")


def _run_task(task: Task) -> list[dict[str, Any]]:
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
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"))
    try:
        pending: set[Future[list[dict[str, Any]]]] = {pool.submit(run, t) for t in tasks}
        while pending:
            finished, pending = wait(pending, return_when=FIRST_COMPLETED)
            for fut in finished:
                yield fut.result()
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


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
        futures = client.map(_run_task, tasks, pure=False)
        for fut in as_completed(futures):
            yield fut.result()
    finally:
        client.close()


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


def _chunks(items: list[tuple[Cell, int]], workers: int) -> list[tuple[tuple[Cell, int], ...]]:
    mujoco = [it for it in items if it[0].world == "mujoco"]
    synthetic = [it for it in items if it[0].world != "mujoco"]
    size = max(1, min(10, len(synthetic) // max(1, 4 * workers)))
    out = [tuple(synthetic[i : i + size]) for i in range(0, len(synthetic), size)]
    return out + [(it,) for it in mujoco]


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
        tasks: list[Task] = [(settings, chunk, spec.seed) for chunk in _chunks(todo, workers)]
        batches = _dask_batches(tasks, scheduler) if scheduler else local_batches(_run_task, tasks, workers)
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
