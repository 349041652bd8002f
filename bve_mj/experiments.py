"""The paper's experiments E1-E10 and their Monte-Carlo runs in the synthetic world.

Seeding: run i of a table draws its scenario, its measurement noise and its planner's
randomness from ``SeedSequence(seed, spawn_key=(i,))``, the same for every experiment,
planner and measurement mode, so comparisons are paired and independent of how runs are
spread over processes.
"""

from __future__ import annotations

import dataclasses
import os
import time
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass

import numpy as np

from bve_mj.config import LossName, ProtocolConfig, Settings, settings_to_dict
from bve_mj.episode import EpisodeResult, run_episode
from bve_mj.errors import ConfigError
from bve_mj.estimation.belief import Belief
from bve_mj.faults import FaultyPlanner, FaultyWorld
from bve_mj.metrics import consistency_metrics, euclidean_metrics, paper_metrics
from bve_mj.planning import Planner, make_planner
from bve_mj.planning.constraints import ConstraintName
from bve_mj.robot import arm_kinematics, get_robot, make_arm_planner
from bve_mj.sim.synthetic import SyntheticWorld
from bve_mj.sim.world import Scenario, World

__all__ = [
    "EXPERIMENTS",
    "PAPER_RESULTS",
    "Experiment",
    "ExperimentSummary",
    "RunRecord",
    "for_robot",
    "parse_experiments",
    "run_synthetic",
    "run_table",
    "sample_scenario",
    "summarise",
    "synthetic_episode",
]


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


def sample_scenario(protocol: ProtocolConfig, rng: np.random.Generator) -> Scenario:
    """The paper's draw: fruit U[-1,1]³, camera U[-2,2]³, estimate = fruit + U[-e,e]³ [m]."""
    fruit = rng.uniform(-protocol.fruit_half_extent_m, protocol.fruit_half_extent_m, 3)
    camera = rng.uniform(-protocol.camera_half_extent_m, protocol.camera_half_extent_m, 3)
    estimate = fruit + rng.uniform(-protocol.initial_error_m, protocol.initial_error_m, 3)
    return Scenario(fruit, camera, estimate)


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


def for_robot(settings: Settings) -> Settings:
    """``settings`` with the workspace sphere of the chosen arm (the paper's for Manipulator-H)."""
    if settings.robot.name == "manipulator_h":
        return settings
    robot = get_robot(settings.robot.name)
    return with_overrides(
        settings,
        constraints={
            "workspace_centre_m": robot.workspace_centre_m,
            "workspace_radius_m": robot.workspace_radius_m,
        },
    )


def synthetic_episode(
    settings: Settings, experiment: Experiment, seed: int, run: int
) -> tuple[Scenario, EpisodeResult]:
    """Run ``run`` of ``experiment`` in the synthetic world: its scenario and its episode.

    Experiments with the arm (E5, E10) start the camera where the arm at ``home`` holds it,
    not at the protocol's random start (which the arm cannot reach); fruit, initial
    estimate and noise are the same draws as every other experiment's run ``run``.
    """
    settings = settings.for_world("synthetic")
    scenario_ss, noise_ss, planner_ss, fault_ss = np.random.SeedSequence(seed, spawn_key=(run,)).spawn(4)
    scenario = sample_scenario(settings.protocol, np.random.default_rng(scenario_ss))
    planner_rng = np.random.default_rng(planner_ss)
    planner: Planner
    if experiment.needs_arm:
        kin = arm_kinematics(settings.robot.name, settings.robot.limit_set)
        p_start, _ = kin.camera_pose(kin.home)
        scenario = dataclasses.replace(scenario, p_world_camera_start=p_start)
        planner = make_arm_planner(
            settings, experiment.loss, experiment.constraints, kin, kin.home, planner_rng
        )
    else:
        planner = make_planner(settings, experiment.loss, experiment.constraints, planner_rng)
    synthetic = SyntheticWorld(settings, scenario, np.random.default_rng(noise_ss))
    world: World = synthetic
    if settings.faults.any:
        fault_rng = np.random.default_rng(fault_ss)
        world = FaultyWorld(synthetic, settings.faults, fault_rng)
        planner = FaultyPlanner(planner, settings.faults.planner_failure_p, fault_rng)
    prior = Belief.isotropic(scenario.initial_estimate, settings.filter.initial_sigma_m)
    return scenario, run_episode(world, planner, prior, settings.filter, settings.protocol.steps)


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


def with_overrides(settings: Settings, **sections: dict[str, object]) -> Settings:
    """A copy of ``settings`` with some fields of some sections replaced (validated)."""
    changes = {
        name: dataclasses.replace(getattr(settings, name), **values)
        for name, values in sections.items()
        if values
    }
    return dataclasses.replace(settings, **changes)
