"""The ``bve-mj`` command.

Exit status: 0 on success; 2 on bad input, with one line naming the field and what is
allowed; 1 on an internal failure (or, for a campaign, when a run crashed); 3 when an
episode could not localise the fruit: out of the arm's reach, or never detected.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib.util
import math
import os
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn

from bve_mj.reporting.atomic import write_json_atomic

if TYPE_CHECKING:
    from bve_mj.campaigns.spec import CampaignSpec
    from bve_mj.config import Settings

__all__ = ["main"]

EXIT_OK, EXIT_FAILURE, EXIT_USAGE, EXIT_NOT_LOCALISED = 0, 1, 2, 3
NOT_LOCALISED = ("unreachable", "never_detected", "ambiguous", "unreliable", "approach_blocked")
"""Episode outcomes that exit 3: the fruit was out of the arm's reach, never seen (or never told
apart from its neighbours), its estimate is not supported by the measurements, or (approach
mode) the arm could not bring the camera close."""
OUTCOME_NOTES = {
    "unreachable": "the arm cannot reach a pose that looks at the fruit's estimate: nothing was measured",
    "never_detected": "no view detected the fruit: the estimate is the prior",
    "ambiguous": "more than one fruit in view fits the estimate about equally well, and no view told "
    "which one is the target: nothing was measured, the estimate is the prior",
    "approach_blocked": "the arm found no reachable pose closer to the fruit (the camera stopped "
    "moving): the fruit is localised but not approached",
    "unreliable": "the final estimate is not supported by the measurements (fewer than two "
    "accepted since the last reset, or most recent ones gated out as disagreeing with it): do not "
    "trust it",
    "stalled": "the camera stopped moving (no better reachable view): more views would only repeat "
    "the same measurement",
}
"""What an outcome means, printed under the episode's summary."""


class _UsageError(Exception):
    pass


class _Parser(argparse.ArgumentParser):
    """argparse that reports bad input in one line and exits 2."""

    def error(self, message: str) -> NoReturn:
        raise _UsageError(f"{self.prog}: {message}")


def _build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="bve-mj", description="Active monocular 3D fruit localisation: BVE + EKF.")
    parser.add_argument("--version", action="version", version=f"bve-mj {_version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    paper = sub.add_parser(
        "paper",
        help="the paper's synthetic protocol, E1-E10, table like the paper's with its numbers beside ours",
        description="Reproduce the paper's table in the synthetic world (Gaussian measurements).",
    )
    paper.add_argument(
        "--experiments",
        default="E1,E2,E3,E4,E5,E6,E7,E8,E9,E10",
        help="comma-separated, e.g. E1,E6",
    )
    paper.add_argument("--runs", default="100", help="runs per experiment (default 100)")
    paper.add_argument("--seed", default="0", help="base seed (default 0)")
    paper.add_argument("--steps", default=None, help="planned views per run (default from settings: 30)")
    paper.add_argument(
        "--measurement", default=None, help="range (the paper's EKF) or camera (default from settings: range)"
    )
    paper.add_argument("--planner", default=None, help="bve, random or circle")
    paper.add_argument("--filter", default=None, help="ekf or ukf (default from settings: ekf)")
    paper.add_argument("--planning-model", default=None, help="paper or consistent")
    paper.add_argument("--optimiser", default=None, help="slsqp or trust-constr")
    paper.add_argument("--robot", default=None, help="arm for E5/E10: manipulator_h, ur5 or panda")
    paper.add_argument("--joint-limits", default=None, help="urdf, or emanual (manipulator_h only)")
    paper.add_argument("--formulation", default=None, help="kinematic feasibility: joint or cartesian")
    paper.add_argument("--config", default=None, help="TOML file of settings (sections as in bve_mj.config)")
    paper.add_argument("--workers", default=None, help="processes (default: all cores)")
    paper.add_argument("--json", default=None, help="write settings and metrics to this JSON file")
    paper.add_argument("--quiet", action="store_true", help="no progress on stderr")

    ep = sub.add_parser(
        "episode",
        help="one closed-loop MuJoCo episode: detect, fuse, plan, IK, drive",
        description="Run one seeded episode in the rendered greenhouse and report it.",
    )
    ep.add_argument("--config", default=None, help="scenario TOML (sections of bve_mj.config.Settings)")
    ep.add_argument("--experiment", default=None, help="constraint set and loss, E1..E10 (default E5)")
    ep.add_argument("--seed", default="0", help="scene, prior and sensor seed (default 0)")
    ep.add_argument("--views", default=None, help="most planned views (default 15)")
    ep.add_argument(
        "--measurement", default=None, help="camera or range (default from settings: camera here)"
    )
    ep.add_argument("--planner", default=None, help="bve, random or circle")
    ep.add_argument("--filter", default=None, help="ekf or ukf (default from settings: ekf)")
    ep.add_argument(
        "--state",
        default=None,
        help="centre (the paper's: range from the size with the prior's radius) or centre_radius "
        "(the radius estimated too; default here)",
    )
    ep.add_argument("--planning-model", default=None, help="paper or consistent")
    ep.add_argument("--robot", default=None, help="manipulator_h, ur5 or panda")
    ep.add_argument("--approach", action="store_true", help="approach mode: end close to the fruit")
    ep.add_argument("--realistic", action="store_true", help="sensor realism on (noise, calibration error)")
    ep.add_argument("--video", default=None, help="write an mp4 of the approach path here")
    ep.add_argument("--plots", default=None, help="write PREFIX_path.png and PREFIX_error.png")
    ep.add_argument("--json", default=None, help="write the episode log (settings, views, outcome) here")
    ep.add_argument("--quiet", action="store_true", help="print only the summary")
    ep.add_argument(
        "--initial-error",
        default=None,
        help="prior error half-width e [m]: along the ray (episode.prior = detection) or per axis "
        "(cube); default 0.05",
    )

    for name, helptext, desc in (
        (
            "campaign",
            "seeded Monte-Carlo runs: experiment x world x planner x measurement x initial error",
            "Run (or resume) a campaign into a directory: runs.sqlite, runs.csv, summary.json, plots.",
        ),
        (
            "recoverability",
            "the paper's recoverability sweep: final error against initial error 0-0.5 m",
            "A campaign over initial errors (default 0:0.5:0.01 m, 10 runs each, E1,E5,E6,E10).",
        ),
    ):
        recover = name == "recoverability"
        c = sub.add_parser(name, help=helptext, description=desc)
        c.add_argument("--out", required=True, help="campaign directory (created; resumed if it holds one)")
        c.add_argument(
            "--experiments",
            default="E1,E5,E6,E10" if recover else "E1,E2,E3,E4,E5,E6,E7,E8,E9,E10",
            help="comma-separated, e.g. E1,E6",
        )
        c.add_argument("--worlds", default="synthetic", help="synthetic, mujoco or synthetic,mujoco")
        c.add_argument("--planners", default="bve", help="any of bve,random,circle")
        c.add_argument(
            "--measurements",
            default=None,
            help="range,camera (default: each world's measurement.kind from the settings; auto = "
            "range in the synthetic world, camera in MuJoCo)",
        )
        c.add_argument(
            "--initial-errors",
            default="0:0.5:0.01" if recover else None,
            help="e0 [m]: X, X,Y,... or START:STOP:STEP (default: "
            + ("0:0.5:0.01)" if recover else "protocol.initial_error_m, episode.initial_error_m)"),
        )
        c.add_argument("--runs", default="10" if recover else "100", help="runs per cell")
        c.add_argument("--seed", default="0", help="base seed (default 0)")
        c.add_argument("--steps", default=None, help="synthetic: planned views per run (default 30)")
        c.add_argument("--views", default=None, help="mujoco: most planned views per run (default 15)")
        c.add_argument(
            "--approach", action="store_true", help="approach mode (eq. 13 term; default episode.approach)"
        )
        c.add_argument(
            "--recovered-mm", default="30", help="a run 'recovered' below this final error (default 30)"
        )
        c.add_argument("--config", default=None, help="TOML file of settings (sections as in bve_mj.config)")
        c.add_argument("--workers", default=None, help="local processes (default: all cores)")
        c.add_argument(
            "--strict",
            action="store_true",
            help="refuse to resume a campaign its store says other code started (default: a note)",
        )
        c.add_argument("--scheduler", default=None, help="Dask distributed scheduler address instead")
        c.add_argument(
            "--no-plots", action="store_true", help="skip the PNG figures (skipped anyway without matplotlib)"
        )
        c.add_argument("--quiet", action="store_true", help="no progress on stderr, no per-cell table")
    sc = sub.add_parser(
        "scenarios",
        help="the greenhouse scenario suite over seeds: the table users judge the project by",
        description="Run every named scenario (examples/scenarios/suite/*.toml) over seeded episodes.",
    )
    sc.add_argument("--only", default=None, help="comma-separated scenario names (default: all)")
    sc.add_argument("--seeds", default="20", help="episodes per scenario (default 20)")
    sc.add_argument("--seed", default="0", help="base seed (default 0)")
    sc.add_argument(
        "--measurement", default=None, help="camera or range for every scenario (default: each file's)"
    )
    sc.add_argument("--filter", default=None, help="ekf or ukf for every scenario (default: each file's)")
    sc.add_argument(
        "--state", default=None, help="centre or centre_radius for every scenario (default: each file's)"
    )
    sc.add_argument("--dir", default=None, help="a folder of scenario TOML files instead of the suite")
    sc.add_argument("--workers", default=None, help="local processes (default: all cores)")
    sc.add_argument("--json", default=None, help="write per-scenario metrics and episode rows here")
    sc.add_argument(
        "--plot",
        default=None,
        help="write the consistency plot (share inside the p-ellipsoid against p) here",
    )
    sc.add_argument("--quiet", action="store_true", help="no progress on stderr")
    cal = sub.add_parser(
        "calibrate",
        help="render the detector against ground truth and fit its noise model (the filter's R)",
        description="Views of the suite's scenes from poses the arm reaches, detected and compared with "
        "the truth; the fitted noise model is written as JSON (set measurement.noise_model to it).",
    )
    cal.add_argument(
        "--out", default="noise_model.json", help="the noise model file (default noise_model.json)"
    )
    cal.add_argument("--only", default=None, help="comma-separated scenario names (default: all)")
    cal.add_argument("--dir", default=None, help="a folder of scenario TOML files instead of the suite")
    cal.add_argument("--scenes", default="8", help="seeded scenes per scenario (default 8)")
    cal.add_argument("--views", default="25", help="views per scene (default 25)")
    cal.add_argument("--seed", default="1", help="base seed (default 1: not the suite's 0)")
    cal.add_argument("--workers", default=None, help="local processes (default: all cores)")
    cal.add_argument("--json", default=None, help="write every view's detection and error here")
    cal.add_argument("--quiet", action="store_true", help="no progress on stderr")
    res = sub.add_parser(
        "results",
        help="run (or resume) the results campaigns and write docs/results.md with its figures",
        description="The paper's table beside ours, recoverability curves, baselines, sample paths.",
    )
    res.add_argument("--out", default="docs/results.md", help="the page (figures go to results/ beside it)")
    res.add_argument("--work", default="results_work", help="campaign directories (resumable)")
    res.add_argument("--runs", default="100", help="synthetic runs per cell (default 100)")
    res.add_argument("--mujoco-runs", default="20", help="MuJoCo episodes per cell (default 20)")
    res.add_argument("--recover-runs", default="10", help="runs per initial error (default 10)")
    res.add_argument("--recover-grid", default="0:0.5:0.01", help="initial errors [m] (default 0:0.5:0.01)")
    res.add_argument("--experiments", default="E1,E2,E3,E4,E5,E6,E7,E8,E9,E10", help="comma-separated")
    res.add_argument("--scenario-seeds", default="20", help="episodes per scenario of the suite (default 20)")
    res.add_argument("--seed", default="0", help="base seed (default 0)")
    res.add_argument("--workers", default=None, help="local processes (default: all cores)")
    res.add_argument("--scheduler", default=None, help="Dask distributed scheduler address instead")
    res.add_argument("--quiet", action="store_true", help="no progress on stderr")
    return parser


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("bve_mj")
    except PackageNotFoundError:  # pragma: no cover (run from a source tree, not installed)
        return "unknown (not installed)"


def _int_arg(name: str, text: str | None, minimum: int) -> int | None:
    from bve_mj.errors import ConfigError

    if text is None:
        return None
    try:
        value = int(text)
    except ValueError:
        raise ConfigError(name, text, f"an integer >= {minimum}") from None
    if value < minimum:
        raise ConfigError(name, text, f"an integer >= {minimum}")
    return value


def _check_output_path(name: str, path: str | None) -> Path | None:
    from bve_mj.errors import ConfigError

    if path is None:
        return None
    p = Path(path)
    if p.is_dir():
        raise ConfigError(name, path, "a file path, not a directory")
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.is_dir():
        raise ConfigError(name, path, f"a path in an existing directory ({parent} does not exist)")
    if not os.access(parent, os.W_OK):
        raise ConfigError(name, path, f"a path in a writable directory ({parent} is not writable)")
    return p


def _progress(enabled: bool) -> Any:
    start = time.perf_counter()

    def report(done: int, total: int) -> None:
        if not enabled:
            return
        width = 30
        filled = int(width * done / total)
        rate = done / max(time.perf_counter() - start, 1e-9)
        eta = (total - done) / rate if rate > 0 else 0.0
        sys.stderr.write(
            f"\r  [{'#' * filled}{'.' * (width - filled)}] {done}/{total} runs, eta {eta:4.0f} s"
        )
        if done == total:
            sys.stderr.write("\n")
        sys.stderr.flush()

    return report


def _fmt(x: float | None, spec: str) -> str:
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else format(x, spec)


def format_table(summaries: dict[str, Any], paper: dict[str, dict[str, float]]) -> list[str]:
    """The paper's table (per-axis, its numbers beside ours), then Euclidean and honesty columns."""
    head = (
        f"{'exp':<4} | {'paper: MAPE%':>12} {'MAE':>6} {'RMSE':>6} {'MSE':>8} "
        f"| {'ours: MAPE%':>11} {'MAE':>6} {'RMSE':>6} {'MSE':>8} "
        f"| {'eucl mean':>9} {'median':>6} {'p95':>6} | {'in3σ%':>5} {'NEES':>5} "
        f"| {'plan ms':>7} {'restor%':>7} {'no-reach':>8}"
    )
    lines = [head, "-" * len(head)]
    for name, s in summaries.items():
        p = paper.get(name, {})
        left = (
            f"{name:<4} | {_fmt(p.get('mape_pct'), '12.2f')} {_fmt(p.get('mae_mm'), '6.1f')} "
            f"{_fmt(p.get('rmse_mm'), '6.1f')} {_fmt(p.get('mse_mm2'), '8.1f')} | "
        )
        m = s.metrics
        lines.append(
            left + f"{m['mape_pct']:11.2f} {m['mae_mm']:6.1f} {m['rmse_mm']:6.1f} {m['mse_mm2']:8.1f} "
            f"| {m['euclid_mean_mm']:9.1f} {m['euclid_median_mm']:6.1f} {m['euclid_p95_mm']:6.1f} "
            f"| {m['inside_3sigma_pct']:5.1f} {m['nees_mean']:5.2f} "
            f"| {m['plan_ms_median']:7.2f} {m['restoring_steps_pct']:7.1f} {m['runs_never_feasible']:8.0f}"
        )
    lines.append(
        "per axis: eqs. 34-37 over runs and axes [mm]; eucl: ‖truth - estimate‖ per run [mm]; "
        "in3σ%: truth inside the final 3σ ellipsoid (97.1% if consistent); NEES: mean (3 if consistent); "
        "restor%: planned steps with no feasible viewpoint within the step limit; "
        "no-reach: runs that never found one (E5/E10: reachable by the arm)"
    )
    return lines


def _given(**values: object) -> dict[str, object]:
    """The options the user gave (not None): only these override the settings file."""
    return {k: v for k, v in values.items() if v is not None}


def paper_settings(args: argparse.Namespace) -> Settings:
    """``bve-mj paper``'s settings: the ``--config`` file (or the defaults), then the options
    given on the command line, resolved for the synthetic world."""
    from bve_mj.config import Settings, load_settings, with_overrides

    settings = load_settings(args.config) if args.config else Settings()
    settings = with_overrides(
        settings,
        measurement=_given(kind=args.measurement),
        filter=_given(kind=args.filter),
        planner=_given(kind=args.planner, planning_model=args.planning_model, optimiser=args.optimiser),
        protocol=_given(steps=_int_arg("steps", args.steps, 1)),
        robot=_given(name=args.robot, joint_limits=args.joint_limits, formulation=args.formulation),
    )
    return settings.for_world("synthetic")


def episode_cli_settings(args: argparse.Namespace) -> Settings:
    """``bve-mj episode``'s settings: the ``--config`` file (or the defaults), then the options
    given on the command line. :func:`bve_mj.loop.mujoco.run_mujoco_episode` resolves the
    closed loop's defaults, the same for the CLI and the Python API."""
    from bve_mj.config import SensorConfig, Settings, load_settings, with_overrides

    settings = load_settings(args.config) if args.config else Settings()
    settings = with_overrides(
        settings,
        episode=_given(
            experiment=args.experiment,
            views=_int_arg("views", args.views, 1),
            initial_error_m=_float_arg("initial-error", args.initial_error, 0.0),
            approach=True if args.approach else None,
        ),
        planner=_given(kind=args.planner, planning_model=args.planning_model),
        measurement=_given(kind=args.measurement),
        filter=_given(kind=args.filter, state=args.state),
        robot=_given(name=args.robot),
    )
    if args.realistic:
        settings = dataclasses.replace(settings, sensor=SensorConfig.realistic())
    return settings


def campaign_inputs(args: argparse.Namespace) -> tuple[Settings, CampaignSpec]:
    """``bve-mj campaign``/``recoverability``: the settings (file, then ``--steps``/``--views``)
    and the spec; axes not given take each world's value from the settings."""
    from bve_mj.campaigns.spec import CampaignSpec, parse_grid
    from bve_mj.config import Settings, load_settings, with_overrides
    from bve_mj.config.experiments import parse_experiments

    settings = load_settings(args.config) if args.config else Settings()
    settings = with_overrides(
        settings,
        protocol=_given(steps=_int_arg("steps", args.steps, 1)),
        episode=_given(views=_int_arg("views", args.views, 1)),
    )
    recovered = _float_arg("recovered-mm", args.recovered_mm, 0.0, strict=True)
    spec = CampaignSpec(
        experiments=tuple(e.name for e in parse_experiments(args.experiments)),
        worlds=tuple(args.worlds.split(",")),  # validated by CampaignSpec
        planners=tuple(args.planners.split(",")),
        measurements=tuple(args.measurements.split(",")) if args.measurements is not None else (),
        initial_errors_m=parse_grid(args.initial_errors) if args.initial_errors is not None else (),
        runs=_int_arg("runs", args.runs, 1) or 1,
        seed=_int_arg("seed", args.seed, 0) or 0,
        approach=True if args.approach else None,
        recovered_mm=recovered or 30.0,
    )
    return settings, spec


def _cmd_paper(args: argparse.Namespace) -> int:
    from bve_mj.campaigns.paper import run_table, table_json
    from bve_mj.config import describe
    from bve_mj.config.experiments import PAPER_RESULTS, parse_experiments

    experiments = parse_experiments(args.experiments)
    runs = _int_arg("runs", args.runs, 1) or 100
    seed = _int_arg("seed", args.seed, 0) or 0
    workers = _int_arg("workers", args.workers, 1)
    json_path = _check_output_path("json", args.json)
    settings = paper_settings(args)
    p = settings.planner
    print(
        f"bve-mj paper: synthetic protocol; measurement={settings.measurement.kind}, planner={p.kind}, "
        f"planning model={p.planning_model}, optimiser={p.optimiser}; {runs} runs, seed {seed}, "
        f"{settings.protocol.steps} steps; arm (E5, E10): {settings.robot.name}, "
        f"{settings.robot.limit_set} limits, {settings.robot.formulation} formulation"
    )
    t0 = time.perf_counter()
    summaries = run_table(
        settings,
        experiments,
        runs,
        seed,
        workers=workers,
        progress=_progress(not args.quiet and sys.stderr.isatty()),
    )
    wall = time.perf_counter() - t0
    for line in format_table(summaries, PAPER_RESULTS):
        print(line)
    print(f"wall time {wall:.1f} s")
    print("settings:")
    for line in describe(settings):
        print("  " + line)
    if json_path is not None:
        write_json_atomic(json_path, table_json(settings, summaries, seed=seed, runs=runs, wall_s=wall))
        print(f"wrote {json_path}")
    return EXIT_OK


def _cmd_episode(args: argparse.Namespace) -> int:
    from bve_mj.errors import ConfigError

    seed = _int_arg("seed", args.seed, 0) or 0
    json_path = _check_output_path("json", args.json)
    video_path = _check_output_path("video", args.video)
    if video_path is not None and video_path.suffix.lower() != ".mp4":
        raise ConfigError("video", args.video, "a path ending in .mp4")
    plots_prefix = _check_output_path("plots", args.plots)
    if plots_prefix is not None:
        from bve_mj.reporting.plots import require_matplotlib

        require_matplotlib("plots", args.plots)
    settings = episode_cli_settings(args)

    import numpy as np

    from bve_mj.loop.mujoco import run_mujoco_episode
    from bve_mj.reporting.video import EpisodeRecorder

    recorder = EpisodeRecorder(video_path) if video_path is not None else None
    try:
        result = run_mujoco_episode(settings, seed, recorder=recorder)
    finally:
        frames = recorder.close() if recorder is not None else 0
    doc = result.to_json()
    s = result.settings
    e = s.episode
    print(
        f"bve-mj episode: seed {seed}, {e.experiment} ({'approach' if e.approach else 'localise'}), "
        f"measurement={s.measurement.kind}, filter={s.filter.kind}, state={s.filter.state}, "
        f"planner={s.planner.kind}, robot={s.robot.name}; target r = {1e3 * result.true_radius_m:.1f} mm"
    )
    if not args.quiet:
        print(
            f"{'view':>4} {'plan':>13} {'detection':>22} {'measured':>8} {'true':>6} "
            f"{'error':>8} {'σmax':>7} {'radius':>14}\n{'':>4} {'':>13} {'':>22} {'range m':>8} "
            f"{'range m':>6} {'mm':>8} {'mm':>7} {'mm':>14}"
        )
        for v, rec in zip(doc["views"], result.result.views, strict=True):
            det = v.get("detection", {})
            shown = f"r {det['radius_px']:.1f} px" if "radius_px" in det else str(det.get("none", "-"))[:22]
            r, sd = rec.belief.radius_m, rec.belief.radius_sigma_m
            rho = (
                None
                if "angular_radius_rad" not in det
                else (r or s.fruit.radius_m) / math.sin(det["angular_radius_rad"])
            )
            measured = f"{rho:8.3f}" if rho is not None else f"{'-':>8}"
            radius = f"{1e3 * r:6.2f} ± {1e3 * sd:5.2f}" if r is not None and sd is not None else "-"
            true_range = float(np.linalg.norm(rec.p_world_camera - result.truth))
            print(
                f"{v['view']:>4} {v['plan_status'] or 'start'!s:>13} {shown:>22} {measured} "
                f"{true_range:6.3f} {v['error_mm']:8.2f} {1e3 * rec.belief.sigma_max_m:7.2f} {radius:>14}"
            )
    radius = ""
    if doc["final_radius_mm"] is not None:
        radius = (
            f"; radius {doc['final_radius_mm']:.2f} ± {doc['final_radius_sigma_mm']:.2f} mm "
            f"(error {doc['radius_error_mm']:+.2f} mm)"
        )
    print(
        f"outcome: {doc['outcome']}; final error {doc['final_error_mm']:.2f} mm "
        f"(NEES {doc['final_nees']:.2f}){radius} after {len(doc['views'])} views; wall {doc['wall_s']:.2f} s"
    )
    print("median per view: " + _stage_times(doc["views"][1:]))
    counts = result.result.event_counts()
    if counts:
        print("events: " + ", ".join(f"{k} x{n}" for k, n in sorted(counts.items())))
    if doc["outcome"] in OUTCOME_NOTES:
        print(OUTCOME_NOTES[doc["outcome"]])
    if video_path is not None:
        print(f"wrote {video_path} ({frames} frames)")
    if plots_prefix is not None:
        from bve_mj.reporting.plots import plot_episode

        for p in plot_episode(doc, plots_prefix):
            print(f"wrote {p}")
    if json_path is not None:
        write_json_atomic(json_path, doc)
        print(f"wrote {json_path}")
    return EXIT_NOT_LOCALISED if doc["outcome"] in NOT_LOCALISED else EXIT_OK


def _stage_times(views: Sequence[dict[str, Any]]) -> str:
    """Median time per view of each stage [ms]: planning (with the joint-space BVE's IK),
    IK in the move (only where a plan carried no joint angles), physics, video recording,
    rendering, detection."""
    import numpy as np

    def median_ms(values: Sequence[float]) -> float:
        return 1e3 * float(np.median(values)) if values else 0.0

    t = [v.get("timings_s", {}) for v in views]
    parts = [f"plan {median_ms([v['plan_s'] for v in views]):.1f} ms (IK included)"]
    if any(x.get("ik_s", 0.0) > 1e-4 for x in t):
        parts.append(f"IK in move {median_ms([x.get('ik_s', 0.0) for x in t]):.1f} ms")
    parts.append(f"control {median_ms([x.get('control_s', 0.0) for x in t]):.1f} ms")
    if any(x.get("record_s", 0.0) > 0.0 for x in t):
        parts.append(f"video recording {median_ms([x.get('record_s', 0.0) for x in t]):.1f} ms")
    parts.append(f"render {median_ms([x.get('render_s', 0.0) for x in t]):.1f} ms")
    parts.append(f"detect {median_ms([x.get('detect_s', 0.0) for x in t]):.1f} ms")
    return ", ".join(parts)


def _float_arg(name: str, text: str | None, minimum: float, strict: bool = False) -> float | None:
    from bve_mj.errors import ConfigError

    if text is None:
        return None
    allowed = f"a number {'>' if strict else '>='} {minimum:g}"
    try:
        value = float(text)
    except ValueError:
        raise ConfigError(name, text, allowed) from None
    if not math.isfinite(value) or value < minimum or (strict and value == minimum):
        raise ConfigError(name, text, allowed)
    return value


def _cmd_campaign(args: argparse.Namespace) -> int:
    from bve_mj.campaigns.runner import run_campaign
    from bve_mj.reporting.campaign_report import format_cells, write_campaign_outputs

    workers = _int_arg("workers", args.workers, 1)
    settings, spec = campaign_inputs(args)
    plots = not args.no_plots
    if plots and importlib.util.find_spec("matplotlib") is None:
        plots = False
        print("bve-mj: matplotlib is not installed, so no figures (pip install 'bve_mj[plots]')")
    print(
        f"bve-mj {args.command}: {len(spec.cells(settings))} cells x {spec.runs} runs "
        f"(worlds {','.join(spec.worlds)}; experiments {','.join(spec.experiments)}; planners "
        f"{','.join(spec.planners)}; measurements {','.join(spec.measurements) or 'from settings'}; "
        f"initial errors "
        f"{_grid_text(spec.initial_errors_m)}), seed {spec.seed} -> {args.out}"
    )
    show = not args.quiet and sys.stderr.isatty()
    result = run_campaign(
        settings, spec, args.out, workers=workers, scheduler=args.scheduler, progress=_progress(show),
        strict=args.strict,
    )  # fmt: skip
    if result.resumed_runs:
        print(f"resumed: {result.resumed_runs} runs were already done, {result.computed_runs} computed now")
    if result.code_change is not None:
        print(
            f"bve-mj: note: resumed under other code: {result.code_change} (--strict refuses)",
            file=sys.stderr,
        )
    if not args.quiet:
        for line in format_cells(result):
            print(line)
    n = result.computed_runs
    print(
        f"wall time {result.wall_s:.1f} s for {n} runs"
        + (f" ({n / result.wall_s:.2f} runs/s)" if n and result.wall_s > 0 else "")
    )
    for path in write_campaign_outputs(result, plots=plots):
        print(f"wrote {path}")
    if result.crashed:
        print(
            f"bve-mj: {len(result.crashed)} runs crashed (kept out of the metrics; a resume retries them):",
            file=sys.stderr,
        )
        for line in result.crashed[:5]:
            print(f"  {line}", file=sys.stderr)
        return EXIT_FAILURE
    return EXIT_OK


def _cmd_results(args: argparse.Namespace) -> int:
    from bve_mj.campaigns.spec import parse_grid
    from bve_mj.config import Settings
    from bve_mj.config.experiments import parse_experiments
    from bve_mj.errors import ConfigError
    from bve_mj.reporting.results_page import PageOptions, build_results_page

    grid = parse_grid(args.recover_grid)
    options = PageOptions(
        runs=_int_arg("runs", args.runs, 1) or 1,
        mujoco_runs=_int_arg("mujoco-runs", args.mujoco_runs, 1) or 1,
        recover_runs=_int_arg("recover-runs", args.recover_runs, 1) or 1,
        recover_grid=grid,
        experiments=tuple(e.name for e in parse_experiments(args.experiments)),
        seed=_int_arg("seed", args.seed, 0) or 0,
        scenario_seeds=_int_arg("scenario-seeds", args.scenario_seeds, 1) or 1,
    )
    workers = _int_arg("workers", args.workers, 1)
    out = _check_output_path("out", args.out)
    assert out is not None
    if out.suffix.lower() != ".md":
        raise ConfigError("out", args.out, "a path ending in .md")
    work = Path(args.work)
    if work.exists() and not work.is_dir():
        raise ConfigError("work", args.work, "a directory (a file is there)")
    from bve_mj.reporting.plots import require_matplotlib

    require_matplotlib()
    show = not args.quiet and sys.stderr.isatty()
    t0 = time.perf_counter()
    written = build_results_page(
        Settings(), out, work, options, workers=workers, scheduler=args.scheduler,
        progress=lambda _name: _progress(show),
    )  # fmt: skip
    print(f"wrote {len(written)} files in {time.perf_counter() - t0:.0f} s; the page: {out}")
    return EXIT_OK


def _cmd_scenarios(args: argparse.Namespace) -> int:
    from bve_mj.campaigns.metrics import consistency_curve
    from bve_mj.campaigns.scenarios import format_suite, load_suite, run_suite, suite_json
    from bve_mj.errors import ConfigError

    seeds = _int_arg("seeds", args.seeds, 1) or 1
    seed = _int_arg("seed", args.seed, 0) or 0
    workers = _int_arg("workers", args.workers, 1)
    json_path = _check_output_path("json", args.json)
    plot_path = _check_output_path("plot", args.plot)
    if plot_path is not None:
        if plot_path.suffix.lower() != ".png":
            raise ConfigError("plot", args.plot, "a path ending in .png")
        from bve_mj.reporting.plots import require_matplotlib

        require_matplotlib("plot", args.plot)
    if args.measurement is not None and args.measurement not in ("camera", "range"):
        raise ConfigError("measurement", args.measurement, "camera or range")
    suite = load_suite(args.dir, args.only.split(",") if args.only is not None else None)
    print(
        f"bve-mj scenarios: {len(suite)} scenarios x {seeds} seeds (base seed {seed}), measurement "
        f"{args.measurement or 'from each file'}, filter {args.filter or 'from each file'}, state "
        f"{args.state or 'from each file'}"
    )
    show = not args.quiet and sys.stderr.isatty()
    result = run_suite(
        suite, seeds=seeds, seed=seed, measurement=args.measurement, filter_kind=args.filter,
        state=args.state, workers=workers, progress=_progress(show),
    )  # fmt: skip
    summaries = {sc.name: result.summary(sc.name) for sc in result.scenarios}
    for line in format_suite(summaries):
        print(line)
    print(f"wall time {result.wall_s:.1f} s")
    if plot_path is not None:
        from bve_mj.reporting.plots import plot_consistency

        curves = {name: s["consistency"] for name, s in summaries.items()}
        curves["all"] = consistency_curve(
            [r["nees"] for rows in result.rows.values() for r in rows if "nees" in r]
        )
        any_settings = next(iter(result.settings.values()))
        title = (
            f"bve-mj scenarios, {result.seeds} seeds: {any_settings.measurement.kind} measurement, "
            f"{any_settings.filter.kind.upper()}, state {any_settings.filter.state}"
        )
        print(f"wrote {plot_consistency(curves, plot_path, title)}")
    if json_path is not None:
        write_json_atomic(json_path, suite_json(result))
        print(f"wrote {json_path}")
    if result.crashed:
        print(f"bve-mj: {len(result.crashed)} episodes crashed:", file=sys.stderr)
        for line in result.crashed[:5]:
            print(f"  {line}", file=sys.stderr)
        return EXIT_FAILURE
    return EXIT_OK


def _cmd_calibrate(args: argparse.Namespace) -> int:
    from bve_mj.campaigns.calibration import calibrate
    from bve_mj.campaigns.scenarios import load_suite
    from bve_mj.errors import ConfigError

    scenes = _int_arg("scenes", args.scenes, 1) or 1
    views = _int_arg("views", args.views, 1) or 1
    seed = _int_arg("seed", args.seed, 0) or 0
    workers = _int_arg("workers", args.workers, 1)
    out = _check_output_path("out", args.out)
    assert out is not None
    if out.suffix.lower() != ".json":
        raise ConfigError("out", args.out, "a path ending in .json")
    json_path = _check_output_path("json", args.json)
    suite = load_suite(args.dir, args.only.split(",") if args.only is not None else None)
    print(f"bve-mj calibrate: {len(suite)} scenarios x {scenes} scenes x {views} views (base seed {seed})")
    show = not args.quiet and sys.stderr.isatty()
    model, report, data = calibrate(
        suite, scenes=scenes, views=views, seed=seed, workers=workers, progress=_progress(show)
    )
    print(
        f"{report['views']} views rendered, {report['refused']} refused, {report['detections']} fitted, "
        f"{report['gross_errors']} gross errors (> 6σ: the wrong fruit; left to the filter's gate)"
    )
    for name, coef in (("centre", model.centre_var_px2), ("radius", model.radius_var_px2)):
        r = report[name]
        terms = " + ".join(
            f"{c:.4g}·{f}" for c, f in zip(coef, ("1", "fit²", "partial²", "elongation²"), strict=True)
        )
        print(
            f"{name:6} variance [px²] = {terms}; error rms {r['error_rms_px']:.3f} px, normalised rms "
            f"{r['z_rms']:.2f}, beyond 2σ {r['beyond_2sigma_pct']:.1f}% (Gaussian 4.6), beyond 3σ "
            f"{r['beyond_3sigma_pct']:.2f}% (0.27)"
        )
    b0, b1 = model.radius_bias_px
    print(f"apparent radius bias {b0:+.3f} {b1:+.3f}·r_px/100 px (removed from every measurement)")
    h, v = model.centre_bias_rel
    print(
        f"the fruit's own centre offset: σ {100 * h:.2f}% of its radius horizontally, {100 * v:.2f}% "
        "vertically (added to the centre's covariance)"
    )
    cc, rc = model.centre_correlation, model.radius_correlation
    print(
        f"views from nearby directions share their errors: correlation {cc.weight:.2f} (centre), "
        f"{rc.weight:.2f} (radius) at 0°, half of it at {cc.half_angle_deg():.0f}° and "
        f"{rc.half_angle_deg():.0f}° (a repeated view counts as the share it adds)"
    )
    write_json_atomic(out, model.to_json())
    print(f'wrote {out} (wall {data.wall_s:.0f} s); use it with [measurement] noise_model = "{out}"')
    if json_path is not None:
        write_json_atomic(json_path, {"model": model.to_json(), "report": report, "rows": list(data.rows)})
        print(f"wrote {json_path}")
    return EXIT_OK


def _grid_text(errors: Sequence[float]) -> str:
    if not errors:
        return "default"
    if len(errors) > 3:
        return f"{errors[0]:g}..{errors[-1]:g} m ({len(errors)} values)"
    return ",".join(f"{e:g}" for e in errors) + " m"


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``bve-mj``; returns the exit status."""
    from bve_mj.errors import BveError, ConfigError

    parser = _build_parser()
    try:
        args = parser.parse_args(argv)
        if args.command is None:
            parser.print_help()
            return EXIT_USAGE
        from bve_mj.threads import one_blas_thread

        # one BLAS thread: results then match a campaign's (its workers pin it too), and a
        # multi-threaded BLAS only adds overhead to 3x3 algebra
        with one_blas_thread():
            if args.command == "paper":
                return _cmd_paper(args)
            if args.command == "episode":
                return _cmd_episode(args)
            if args.command in ("campaign", "recoverability"):
                return _cmd_campaign(args)
            if args.command == "results":
                return _cmd_results(args)
            if args.command == "scenarios":
                return _cmd_scenarios(args)
            if args.command == "calibrate":
                return _cmd_calibrate(args)
        raise _UsageError(f"bve-mj: unknown command {args.command!r}")  # pragma: no cover
    except _UsageError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except ConfigError as exc:
        print(f"bve-mj: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except BveError as exc:
        print(f"bve-mj: failed: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    except KeyboardInterrupt:
        print(
            "bve-mj: interrupted (a campaign keeps every finished run: the same command resumes it)",
            file=sys.stderr,
        )
        return 130
    except Exception as exc:  # internal failure: one line, exit 1 (BVE_MJ_DEBUG=1 for the traceback)
        if os.environ.get("BVE_MJ_DEBUG"):
            raise
        print(f"bve-mj: internal error: {type(exc).__name__}: {exc}", file=sys.stderr)
        return EXIT_FAILURE


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
