"""``bve-mj campaign``, ``recoverability`` and ``results``: seeded Monte-Carlo campaigns."""

from __future__ import annotations

import argparse
import importlib.util
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

from bve_mj.cli.args import (
    EXIT_FAILURE,
    EXIT_OK,
    check_output_path,
    float_arg,
    given,
    grid_text,
    int_arg,
    progress_printer,
)

if TYPE_CHECKING:
    from bve_mj.campaigns.spec import CampaignSpec
    from bve_mj.config import Settings

__all__ = ["campaign_inputs", "cmd_campaign", "cmd_results"]


def campaign_inputs(args: argparse.Namespace) -> tuple[Settings, CampaignSpec]:
    """``bve-mj campaign``/``recoverability``: the settings (file, then ``--steps``/``--views``)
    and the spec; axes not given take each world's value from the settings."""
    from bve_mj.campaigns.spec import CampaignSpec, parse_grid
    from bve_mj.config import Settings, load_settings, with_overrides
    from bve_mj.config.experiments import parse_experiments

    settings = load_settings(args.config) if args.config else Settings()
    settings = with_overrides(
        settings,
        protocol=given(steps=int_arg("steps", args.steps, 1)),
        episode=given(views=int_arg("views", args.views, 1)),
    )
    recovered = float_arg("recovered-mm", args.recovered_mm, 0.0, strict=True)
    spec = CampaignSpec(
        experiments=tuple(e.name for e in parse_experiments(args.experiments)),
        worlds=tuple(args.worlds.split(",")),  # validated by CampaignSpec
        planners=tuple(args.planners.split(",")),
        measurements=tuple(args.measurements.split(",")) if args.measurements is not None else (),
        initial_errors_m=parse_grid(args.initial_errors) if args.initial_errors is not None else (),
        runs=int_arg("runs", args.runs, 1) or 1,
        seed=int_arg("seed", args.seed, 0) or 0,
        approach=True if args.approach else None,
        recovered_mm=recovered or 30.0,
    )
    return settings, spec


def cmd_campaign(args: argparse.Namespace) -> int:
    from bve_mj.campaigns.runner import run_campaign
    from bve_mj.reporting.campaign_report import format_cells, write_campaign_outputs

    workers = int_arg("workers", args.workers, 1)
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
        f"{grid_text(spec.initial_errors_m)}), seed {spec.seed} -> {args.out}"
    )
    show = not args.quiet and sys.stderr.isatty()
    result = run_campaign(
        settings, spec, args.out, workers=workers, scheduler=args.scheduler, progress=progress_printer(show),
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


def cmd_results(args: argparse.Namespace) -> int:
    from bve_mj.campaigns.spec import parse_grid
    from bve_mj.config import Settings
    from bve_mj.config.experiments import parse_experiments
    from bve_mj.errors import ConfigError
    from bve_mj.reporting.results_page import PageOptions, build_results_page

    grid = parse_grid(args.recover_grid)
    options = PageOptions(
        runs=int_arg("runs", args.runs, 1) or 1,
        mujoco_runs=int_arg("mujoco-runs", args.mujoco_runs, 1) or 1,
        recover_runs=int_arg("recover-runs", args.recover_runs, 1) or 1,
        recover_grid=grid,
        experiments=tuple(e.name for e in parse_experiments(args.experiments)),
        seed=int_arg("seed", args.seed, 0) or 0,
        scenario_seeds=int_arg("scenario-seeds", args.scenario_seeds, 1) or 1,
    )
    workers = int_arg("workers", args.workers, 1)
    out = check_output_path("out", args.out)
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
        progress=lambda _name: progress_printer(show),
    )  # fmt: skip
    print(f"wrote {len(written)} files in {time.perf_counter() - t0:.0f} s; the page: {out}")
    return EXIT_OK
