"""``docs/results.md``: the paper's table beside ours, recoverability, baselines, sample paths.

One command (``bve-mj results``) runs, or resumes, four campaigns in a work directory and
writes the page and its figures; every number on the page comes from those campaigns and
every figure says the command and seed that made it.
"""

from __future__ import annotations

import datetime
import itertools
import json
import os
import platform
import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from bve_mj.campaigns.runner import CampaignResult, run_campaign
from bve_mj.campaigns.scenarios import format_suite, load_suite, run_suite, suite_json
from bve_mj.campaigns.spec import CampaignSpec, Cell
from bve_mj.config import Settings
from bve_mj.config.experiments import EXPERIMENTS, PAPER_RESULTS
from bve_mj.errors import ConfigError
from bve_mj.reporting.atomic import write_json_atomic, write_text_atomic
from bve_mj.reporting.campaign_report import cell_summary, plot_campaign, write_campaign_outputs

__all__ = ["PageOptions", "build_results_page"]


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


def _campaigns(o: PageOptions) -> dict[str, CampaignSpec]:
    recover_exps = tuple(e for e in ("E1", "E5", "E6", "E10") if e in o.experiments) or o.experiments[:1]
    approach_exps = ("E5",) if "E5" in o.experiments else o.experiments[:1]
    return {
        "synthetic": CampaignSpec(
            experiments=o.experiments, worlds=("synthetic",), planners=("bve", "random", "circle"),
            measurements=("range", "camera"), runs=o.runs, seed=o.seed,
        ),
        "mujoco": CampaignSpec(
            experiments=o.experiments, worlds=("mujoco",), planners=("bve", "random", "circle"),
            measurements=("camera",), runs=o.mujoco_runs, seed=o.seed,
        ),
        "recoverability": CampaignSpec(
            experiments=recover_exps, worlds=("synthetic",), measurements=("range",),
            initial_errors_m=o.recover_grid, runs=o.recover_runs, seed=o.seed,
        ),
        "recoverability_approach": CampaignSpec(
            experiments=approach_exps, worlds=("synthetic",), measurements=("range",),
            initial_errors_m=o.recover_grid, runs=o.recover_runs, seed=o.seed, approach=True,
        ),
    }  # fmt: skip


def _cmd(name: str, spec: CampaignSpec) -> str:
    kind = "recoverability" if name.startswith("recoverability") else "campaign"
    parts = [
        f"bve-mj {kind} --out WORK/{name}",
        f"--experiments {','.join(spec.experiments)}",
        f"--worlds {','.join(spec.worlds)}",
        f"--planners {','.join(spec.planners)}",
        f"--measurements {','.join(spec.measurements)}",
    ]
    if spec.initial_errors_m:
        g = spec.initial_errors_m
        parts.append(f"--initial-errors {g[0]:g}:{g[-1]:g}:{round(g[1] - g[0], 9):g}")
    parts.append(f"--runs {spec.runs} --seed {spec.seed}")
    if spec.approach:
        parts.append("--approach")
    return " ".join(parts)


Summaries = dict[Cell, dict[str, Any]]


def _fmt(x: Any, spec: str = ".1f") -> str:
    return "–" if x is None or (isinstance(x, float) and not np.isfinite(x)) else format(x, spec)


def _summaries(result: CampaignResult) -> Summaries:
    return {c: cell_summary(result.cell_rows(c), result.spec.recovered_mm) for c in result.cells}


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
    lines = [
        "| exp | BVE | random | circle | BVE best? |",
        "|---|---|---|---|---|",
    ]
    wins = 0
    for name in o.experiments:
        vals = {
            p: _find(summ, experiment=name, planner=p, measurement=measurement).get("euclid_mean_mm")
            for p in ("bve", "random", "circle")
        }
        b, r, c = (np.inf if v is None else float(v) for v in vals.values())
        best = bool(np.isfinite(b) and b <= min(r, c))
        wins += bool(best)
        digits = ".1f" if measurement == "range" else ".2f"
        lines.append(
            f"| {name} | {_fmt(vals['bve'], digits)} | {_fmt(vals['random'], digits)} "
            f"| {_fmt(vals['circle'], digits)} | {'yes' if best else 'no'} |"
        )
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


def _version() -> str:
    """The package version and, in a git checkout, the commit (``+modified`` when the
    package's own files differ from it)."""
    import subprocess
    from importlib.metadata import PackageNotFoundError, version

    try:
        v = version("bve_mj")
    except PackageNotFoundError:  # pragma: no cover
        v = "unknown"
    here = Path(__file__).resolve().parent

    def git(*args: str) -> str:
        return subprocess.run(
            ["git", "-C", str(here), *args], capture_output=True, text=True, timeout=5, check=True
        ).stdout.strip()

    try:
        commit = git("rev-parse", "--short", "HEAD")
        modified = git("status", "--porcelain", "--untracked-files=no", "--", str(here))
    except (OSError, subprocess.SubprocessError):
        return v
    return f"{v}, commit {commit}{' +modified' if modified else ''}"


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


def build_results_page(
    settings: Settings,
    out_md: Path,
    work: Path,
    options: PageOptions,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    progress: Callable[[str], Callable[[int, int], None]] | None = None,
    log: Callable[[str], None] = print,
) -> list[Path]:
    """Run or resume the page's campaigns in ``work``, write ``out_md`` and its figures in
    ``out_md``'s folder under ``results/``; returns the files written."""
    t0 = time.perf_counter()
    figures = out_md.parent / "results"
    figures.mkdir(parents=True, exist_ok=True)
    specs = _campaigns(options)
    results: dict[str, CampaignResult] = {}
    for name, spec in specs.items():
        n = len(spec.cells(settings)) * spec.runs
        log(f"campaign {name}: {n} runs -> {work / name}")
        results[name] = run_campaign(
            settings, spec, work / name, workers=workers, scheduler=scheduler,
            progress=progress(name) if progress else None,
        )  # fmt: skip
        write_campaign_outputs(results[name], plots=True)
        if results[name].crashed:
            log(f"  {len(results[name].crashed)} runs crashed (left out): {results[name].crashed[0]}")
    suites = {
        m: _scenario_suite(work, options, m, workers, log, progress(f"scenarios {m}") if progress else None)
        for m in ("camera", "range")
    }
    written: list[Path] = []

    def copy(name: str, png: str, as_name: str) -> str:
        src = work / name / png
        if not src.exists():
            return ""
        dst = figures / as_name
        shutil.copyfile(src, dst)
        written.append(dst)
        return f"results/{as_name}"

    # figures made for the page: error against views for E5 (or the first experiment)
    focus = "E5" if "E5" in options.experiments else options.experiments[0]
    for name, label in (("synthetic", "synthetic"), ("mujoco", "mujoco")):
        r = results[name]
        sub = [c for c in r.cells if c.experiment == focus]
        written += plot_campaign(r, sub, figures, prefix=f"{label}_{focus}_")

    syn, muj = _summaries(results["synthetic"]), _summaries(results["mujoco"])
    rec = {**_summaries(results["recoverability"]), **_summaries(results["recoverability_approach"])}
    rec_png = copy("recoverability", "recoverability.png", "recoverability.png")
    app_png = copy("recoverability_approach", "recoverability.png", "recoverability_approach.png")
    cmds = {name: _cmd(name, spec) for name, spec in specs.items()}
    wall = time.perf_counter() - t0
    computed = sum(r.computed_runs for r in results.values())
    total = sum(len(r.rows) for r in results.values())
    run_hours = sum(float(row.get("wall_s") or 0.0) for r in results.values() for row in r.rows) / 3600
    now = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    md: list[str] = [
        "# Results",
        "",
        f"Generated by `{options.command()}` on {now} from bve_mj {_version()} "
        f"({platform.machine()}, {os.cpu_count()} cores; {total} runs, {run_hours:.2f} h of run time "
        f"in all; {computed} computed in this call, which took {wall:.0f} s). Every number below comes from "
        "the four campaigns it ran, each resumable and reproducible alone with the command shown "
        "(`WORK` = the `--work` directory; per-run rows are in `WORK/<name>/runs.csv`). Settings: "
        "the defaults of `bve_mj.config` (`bve-mj paper` prints every one with its reason).",
        "",
        "## 1. The paper's table beside ours",
        "",
        f"Synthetic world: the paper's protocol (fruit U[-1,1]³ m, camera U[-2,2]³ m, estimate = fruit + "
        f"U[-e0,e0]³, e0 = {settings.protocol.initial_error_m:g} m, "
        f"{settings.protocol.steps} planned views), "
        f"{options.runs} runs per experiment, seed {options.seed}; `range` is the paper's EKF (range-only "
        "measurements), `camera` our bearing + range model. MuJoCo: closed-loop episodes in the rendered "
        f"greenhouse (camera measurements from the detector, up to {settings.episode.views} views, stop "
        f"at σ ≤ {1e3 * settings.episode.stop_sigma_m:g} mm), {options.mujoco_runs} episodes per experiment. "
        "Per-axis MAE and RMSE as the paper's eqs. 35-36 [mm]; eucl. = ‖estimate − truth‖ per run [mm]; "
        "NEES: mean normalised estimation error squared (3 if the filter's covariance is honest).",
        "",
        *_paper_table(syn, muj, options),
        "",
        f"Commands: `{cmds['synthetic']}` and `{cmds['mujoco']}`.",
        "",
        "## 2. Recoverability",
        "",
        f"Final error against the initial error e0 (the paper's sweep: {len(options.recover_grid)} values "
        f"from {options.recover_grid[0]:g} to {options.recover_grid[-1]:g} m, {options.recover_runs} runs "
        "each, range-only measurements as in the paper). Blue RMSE, yellow MAE (per axis), red MSE "
        "(right axis), dashed the Euclidean median.",
        "",
        *_recover_table(rec),
        "",
    ]
    if rec_png:
        md += [f"![recoverability]({rec_png})", "", f"*`{cmds['recoverability']}`*", ""]
    if app_png:
        md += [
            f"![recoverability, approach mode]({app_png})",
            "",
            f"*Approach mode (eq. 13 term on): `{cmds['recoverability_approach']}`*",
            "",
        ]
    md += ["## 3. The BVE against the baselines", ""]
    md += [
        "Mean Euclidean error [mm] of the BVE and of two baselines under the same constraints and step "
        "limit: `random` (a random feasible viewpoint within the step) and `circle` (orbit the estimate). "
        "Runs are paired: run i has the same fruit, prior and noise draws in every column.",
        "",
        "### Synthetic, range-only",
        "",
        *_baseline_table(syn, "synthetic", "range", options),
        "",
        "### Synthetic, camera",
        "",
        *_baseline_table(syn, "synthetic", "camera", options),
        "",
        "### MuJoCo, camera (closed loop)",
        "",
        *_baseline_table(muj, "mujoco", "camera", options),
        "",
    ]

    def figure(name: str, alt: str, caption: str) -> list[str]:
        png = figures / name
        return [f"![{alt}](results/{name})", "", f"*{caption}*", ""] if png.exists() else []

    for label in ("synthetic", "mujoco"):
        md += figure(
            f"{label}_{focus}_error_by_view.png",
            f"error against views, {label} {focus}",
            f"Median and IQR of the error after each view, {label} world, {focus}, every planner "
            f"and measurement: from `{cmds[label]}`.",
        )
    md += [
        "## The greenhouse scenario suite",
        "",
        f"`bve-mj scenarios --seeds {options.scenario_seeds} --seed {options.seed} --measurement M`: "
        "every named scene of `examples/scenarios/suite/` (trusses of touching fruit, fruit types, "
        "ripeness, occlusion, light, sensors), one seeded closed-loop episode per seed. "
        "**silent** counts confident wrong answers: it must be 0.",
        "",
    ]
    for m, doc in suites.items():
        md += [f"### Measurement: {m}", "", *format_suite(doc["scenarios"], markdown=True), ""]
    md += ["## 4. Sample paths", ""]
    for label in ("synthetic", "mujoco"):
        md += figure(
            f"{label}_{focus}_sample_paths.png",
            f"sample paths, {label} {focus}",
            f"Run 0 of {focus} for each planner and measurement, {label} world: camera positions "
            f"light to dark blue in time, the estimate green, the true fruit red. From `{cmds[label]}`.",
        )
    written.append(write_text_atomic(out_md, "\n".join(md)))
    return written
