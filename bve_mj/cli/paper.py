"""``bve-mj paper``: the paper's synthetic protocol, E1-E10."""

from __future__ import annotations

import argparse
import sys
import time
from typing import TYPE_CHECKING

from bve_mj.atomic import write_json_atomic
from bve_mj.cli.args import EXIT_OK, check_output_path, given, int_arg, progress_printer
from bve_mj.reporting.tables import format_table

if TYPE_CHECKING:
    from bve_mj.config import Settings

__all__ = ["cmd_paper", "paper_settings"]


def paper_settings(args: argparse.Namespace) -> Settings:
    """``bve-mj paper``'s settings: the ``--config`` file (or the defaults), then the options
    given on the command line, resolved for the synthetic world."""
    from bve_mj.config import Settings, load_settings, with_overrides

    settings = load_settings(args.config) if args.config else Settings()
    settings = with_overrides(
        settings,
        measurement=given(kind=args.measurement),
        filter=given(kind=args.filter),
        planner=given(kind=args.planner, planning_model=args.planning_model, optimiser=args.optimiser),
        protocol=given(steps=int_arg("steps", args.steps, 1)),
        robot=given(name=args.robot, joint_limits=args.joint_limits, formulation=args.formulation),
    )
    return settings.for_world("synthetic")


def cmd_paper(args: argparse.Namespace) -> int:
    from bve_mj.campaigns.paper import run_table, table_json
    from bve_mj.config import describe
    from bve_mj.config.experiments import PAPER_RESULTS, parse_experiments

    experiments = parse_experiments(args.experiments)
    runs = int_arg("runs", args.runs, 1) or 100
    seed = int_arg("seed", args.seed, 0) or 0
    workers = int_arg("workers", args.workers, 1)
    json_path = check_output_path("json", args.json)
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
        progress=progress_printer(not args.quiet and sys.stderr.isatty()),
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
