"""``docs/results.md``: the paper's table beside ours, recoverability, baselines, sample paths.

One command (``bve-mj results``) runs, or resumes, four campaigns in a work directory and
writes the page and its figures; every number on the page comes from those campaigns and
every figure says the command and seed that made it."""

from __future__ import annotations

import datetime
import os
import platform
import shutil
import time
from collections.abc import Callable
from pathlib import Path

from bve_mj.atomic import write_text_atomic
from bve_mj.campaigns.runner import CampaignResult, run_campaign
from bve_mj.campaigns.scenarios import format_suite
from bve_mj.campaigns.spec import MEASUREMENTS, PLANNERS, CampaignSpec
from bve_mj.config import Settings
from bve_mj.reporting.campaign_plots import plot_campaign
from bve_mj.reporting.campaign_report import cell_summary, write_campaign_outputs
from bve_mj.reporting.results_tables import (
    PageOptions,
    Summaries,
    _baseline_table,
    _paper_table,
    _recover_table,
    _scenario_suite,
)

__all__ = ["PageOptions", "build_results_page"]


def _campaigns(o: PageOptions) -> dict[str, CampaignSpec]:
    recover_exps = tuple(e for e in ("E1", "E5", "E6", "E10") if e in o.experiments) or o.experiments[:1]
    approach_exps = ("E5",) if "E5" in o.experiments else o.experiments[:1]
    return {
        "synthetic": CampaignSpec(
            experiments=o.experiments, worlds=("synthetic",), planners=PLANNERS,
            measurements=MEASUREMENTS, runs=o.runs, seed=o.seed,
        ),
        "mujoco": CampaignSpec(
            experiments=o.experiments, worlds=("mujoco",), planners=PLANNERS,
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


def _summaries(result: CampaignResult) -> Summaries:
    return {c: cell_summary(result.cell_rows(c), result.spec.recovered_mm) for c in result.cells}


def _version() -> str:
    """The package version and, in a git checkout, the commit (``+modified`` when the
    package's own files differ from it)."""
    import subprocess
    from importlib.metadata import PackageNotFoundError, version

    try:
        v = version("bve_mj")
    except PackageNotFoundError:  # pragma: no cover
        v = "unknown"
    here = Path(__file__).resolve().parents[1]  # the package (this module moved into reporting/)

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
        "Mean Euclidean error [mm] of the BVE and of three baselines under the same constraints and step "
        "limit: `random` (a random feasible viewpoint within the step), `circle` (orbit the estimate) and "
        "`fixed` (three fixed views, the closest published monocular method's protocol). "
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
