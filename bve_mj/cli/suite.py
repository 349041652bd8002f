"""``bve-mj scenarios`` and ``bve-mj calibrate``: the greenhouse scenario suite and the
detector's noise calibration."""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast, get_args

from bve_mj.atomic import write_json_atomic
from bve_mj.cli.args import EXIT_FAILURE, EXIT_OK, check_output_path, int_arg, progress_printer

__all__ = ["cmd_calibrate", "cmd_scenarios"]

if TYPE_CHECKING:
    from bve_mj.campaigns.fruit_suite import FruitSuiteResult
    from bve_mj.estimation.noise import NoiseModel


def cmd_scenarios(args: argparse.Namespace) -> int:
    from bve_mj.campaigns.scenarios import format_suite, load_suite, run_suite, suite_json
    from bve_mj.errors import ConfigError
    from bve_mj.estimation.metrics import consistency_curve

    seeds = int_arg("seeds", args.seeds, 1) or 1
    seed = int_arg("seed", args.seed, 0) or 0
    workers = int_arg("workers", args.workers, 1)
    json_path = check_output_path("json", args.json)
    plot_path = check_output_path("plot", args.plot)
    if plot_path is not None:
        if plot_path.suffix.lower() != ".png":
            raise ConfigError("plot", args.plot, "a path ending in .png")
        from bve_mj.reporting.plots import require_matplotlib

        require_matplotlib("plot", args.plot)
    if args.measurement is not None and args.measurement not in ("camera", "range"):
        raise ConfigError("measurement", args.measurement, "camera or range")
    if args.fruits is not None and args.fruits not in ("target", "all"):
        raise ConfigError("fruits", args.fruits, "one of target, all")
    suite = load_suite(args.dir, args.only.split(",") if args.only is not None else None)
    if args.planners is not None and args.fruits != "all":
        raise ConfigError("planners", args.planners, "only with --fruits all")
    pick = int_arg("pick", args.pick, 0)
    if pick is not None and args.fruits != "all":
        raise ConfigError("pick", args.pick, "only with --fruits all")
    if args.fruits == "all":
        for name in ("measurement", "filter", "state", "plot"):
            if getattr(args, name) is not None:
                raise ConfigError(
                    name, getattr(args, name), "not with --fruits all (camera, ekf, centre_radius)"
                )
        return _every_fruit(args, suite, seeds, seed, workers or os.cpu_count() or 1, json_path, pick)
    print(
        f"bve-mj scenarios: {len(suite)} scenarios x {seeds} seeds (base seed {seed}), measurement "
        f"{args.measurement or 'from each file'}, filter {args.filter or 'from each file'}, state "
        f"{args.state or 'from each file'}"
    )
    show = not args.quiet and sys.stderr.isatty()
    result = run_suite(
        suite, seeds=seeds, seed=seed, measurement=args.measurement, filter_kind=args.filter,
        state=args.state, workers=workers, progress=progress_printer(show),
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
    return _exit_status(result.crashed)


def _every_fruit(
    args: argparse.Namespace,
    suite: list[Any],
    seeds: int,
    seed: int,
    workers: int,
    json_path: Path | None,
    pick: int | None = None,
) -> int:
    """``bve-mj scenarios --fruits all``: every ripe fruit of each scene (``pick``: picking
    rounds for every scene, approach mode on; None: each file's)."""
    from bve_mj.campaigns.fruit_suite import (
        compare_fruit_planners,
        format_fruit_suite,
        format_harvests,
        run_fruit_suites,
    )
    from bve_mj.campaigns.scenarios import suite_json_clean
    from bve_mj.config import PlannerKind
    from bve_mj.errors import ConfigError

    allowed = get_args(PlannerKind)
    planners: list[PlannerKind | None] = [None]
    if args.planners is not None:
        names = [p.strip() for p in str(args.planners).split(",")]
        bad = [p for p in names if p not in allowed] or ([] if len(set(names)) == len(names) else names)
        if bad or not names:
            raise ConfigError("planners", args.planners, f"distinct names from {', '.join(allowed)}")
        planners = [cast("PlannerKind", p) for p in names]
    picking = "" if pick is None else f", harvest picking up to {pick} rounds"
    print(
        f"bve-mj scenarios --fruits all: {len(suite)} scenarios x {seeds} seeds (base seed {seed}){picking}"
    )
    show = not args.quiet and sys.stderr.isatty()
    # every planner on each seed in turn, in one pool: a worker builds each seed's scene once
    by_planner = run_fruit_suites(
        suite,
        planners,
        seeds=seeds,
        seed=seed,
        workers=workers,
        progress=progress_printer(show),
        pick_rounds=pick,
    )
    results: dict[str, FruitSuiteResult] = {p or "file": r for p, r in by_planner.items()}
    for planner, result in by_planner.items():
        if planner is not None:
            print(f"planner {planner}:")
        summaries = {sc.name: result.summary(sc.name) for sc in result.scenarios}
        for line in format_fruit_suite(summaries) + format_harvests(summaries):
            print(line)
    wall_s = next(iter(results.values())).wall_s
    print(f"wall time {wall_s:.1f} s")
    if len(results) > 1:
        print("paired on seeds:")
        for line in compare_fruit_planners(results, reference=next(iter(results))):
            print(line)
    if json_path is not None:
        runs = {name: {sc.name: r.summary(sc.name) for sc in r.scenarios} for name, r in results.items()}
        doc: dict[str, Any] = {
            "seed": seed,
            "seeds": seeds,
            "wall_s": wall_s,
        }
        doc["scenarios" if planners == [None] else "planners"] = runs.get("file", runs)
        write_json_atomic(json_path, suite_json_clean(doc))
        print(f"wrote {json_path}")
    return _exit_status([c for r in results.values() for c in r.crashed])


def _exit_status(crashed: list[str]) -> int:
    """1 (and the first crashes on stderr) when episodes crashed, else 0."""
    if crashed:
        print(f"bve-mj: {len(crashed)} episodes crashed:", file=sys.stderr)
        for line in crashed[:5]:
            print(f"  {line}", file=sys.stderr)
        return EXIT_FAILURE
    return EXIT_OK


def cmd_calibrate(args: argparse.Namespace) -> int:
    from bve_mj.campaigns.calibration import calibrate
    from bve_mj.campaigns.drawn_scenes import write_drawn_scenes
    from bve_mj.campaigns.scenarios import load_suite
    from bve_mj.errors import ConfigError
    from bve_mj.estimation.partial_colour import MIN_FRUITS, MIN_VIEWS

    scenes = int_arg("scenes", args.scenes, 1) or 1
    views = int_arg("views", args.views, 1) or 1
    seed = int_arg("seed", args.seed, 0) or 0
    workers = int_arg("workers", args.workers, 1)
    out = check_output_path("out", args.out)
    assert out is not None
    if out.suffix.lower() != ".json":
        raise ConfigError("out", args.out, "a path ending in .json")
    json_path = check_output_path("json", args.json)
    drawn_count = int_arg("drawn", args.drawn, 0) or 0
    twin_views = int_arg("twin_views", args.twin_views, 0) or 0
    suite = load_suite(args.dir, args.only.split(",") if args.only is not None else None)
    also = f" + {drawn_count} drawn scenes (draw seed {seed}) x 1 scene" if drawn_count else ""
    print(
        f"bve-mj calibrate: {len(suite)} scenarios x {scenes} scenes{also}, {views} views each "
        f"(base seed {seed})"
    )
    show = not args.quiet and sys.stderr.isatty()
    with tempfile.TemporaryDirectory(prefix="bve_mj_drawn_") as folder:
        drawn = load_suite(write_drawn_scenes(folder, drawn_count, seed)[0].parent) if drawn_count else []
        model, report, data = calibrate(
            suite, scenes=scenes, views=views, seed=seed, workers=workers, progress=progress_printer(show),
            every_fruit=args.every_fruit, drawn=drawn, twin_views=twin_views,
        )  # fmt: skip
    neighbours = (
        f"its neighbours (the every-fruit detector): {report['every_fruit_detections']} measured, "
        f"{report['every_fruit_refused']} refused; "
    )
    print(
        f"{report['views']} views rendered, the target refused in {report['refused']}; "
        f"{neighbours if args.every_fruit else ''}{report['detections']} fitted, {report['gross_errors']} "
        "gross errors (> 6σ: the wrong fruit; left to the filter's gate)"
    )
    for name, coef in (("centre", model.centre_var_px2), ("radius", model.radius_var_px2)):
        r = report[name]
        names = ("1", "fit²", "partial²", "elongation²", "scale²", "neighbour²", "neighbour·fit²", "scale⁴")
        terms = " + ".join(f"{c:.4g}·{f}" for c, f in zip(coef, names, strict=True))
        print(
            f"{name:6} variance [px²] = {terms}; error rms {r['error_rms_px']:.3f} px, normalised rms "
            f"{r['z_rms']:.2f}, beyond 2σ {r['beyond_2sigma_pct']:.1f}% (Gaussian 4.6), beyond 3σ "
            f"{r['beyond_3sigma_pct']:.2f}% (0.27)"
        )
    b0, b1 = model.radius_bias_px
    print(f"apparent radius bias {b0:+.3f} {b1:+.3f}·r_px/100 px (removed from every measurement)")
    for line in offset_lines(model):
        print(line)
    cc, rc = model.centre_correlation, model.radius_correlation
    print(
        f"views from nearby directions share their errors: correlation {cc.weight:.2f} (centre), "
        f"{rc.weight:.2f} (radius) at 0°, half of it at {cc.half_angle_deg():.0f}° and "
        f"{rc.half_angle_deg():.0f}° (a repeated view counts as the share it adds)"
    )
    twins = report.get("twins")
    if twins is not None and len(twins["table"]) < 3:
        print(f"views from one place: {twins['pairs']} twin pairs, too few to fit (counted by direction)")
    elif twins is not None:
        cc, rc = model.centre_correlation, model.radius_correlation
        print(
            f"views from one place share more: {twins['pairs']} twin pairs, nearby share "
            f"{cc.nearby:.2f} (centre), {rc.nearby:.2f} (radius), over {1e3 * cc.length_m:.0f} and "
            f"{1e3 * rc.length_m:.0f} mm (a camera that holds learns almost nothing new)"
        )
    print(
        f"a fruit the detector refuses errs more: variance × exp({model.refusal_scale:.2f} · refused share) "
        f"({report.get('refusal_fruits', 0)} fruits; scales the claimed covariance)"
    )
    print(
        f"tail: the claimed covariance × {model.tail_scale:.2f} holds 99.9% of the errors of episode-like "
        f"estimates (3-6 views of a fruit fused) in its 99.9% ellipsoid; × {model.view_tail_scale:.2f} those "
        "of single views (what size-only episodes claim with)"
    )
    print(
        f"outliers: {100 * model.outlier_share:.1f}% of views err {model.outlier_scale:.1f}x the σ above "
        "(a scale mixture the tracker fuses with)"
    )
    short = report["partial_colour"]
    if model.partial_colour_offset > 0.0 or model.partial_colour_view != (0.0, 1.0, 1.0):
        d, kc, kr = model.partial_colour_view
        print(
            f"a detector of a class short of red ({short['views']} views, {short['fruits']} fruits): "
            f"apparent radius {d:+.3f} px beyond the bias, variance x{kc:.2f} (centre), x{kr:.2f} "
            f"(radius); its fruits' own offset {model.partial_colour_offset:.3e} of the radius²"
        )
    else:
        print(
            f"a detector of a class short of red: {short['views']} views, {short['fruits']} fruits, too few "
            f"to fit its terms (>= {MIN_VIEWS} views, {MIN_FRUITS} fruits): none in this model (calibrate "
            "the turning scene alone and run benchmarks/partial_colour_offset.py on its rows)"
        )
    write_json_atomic(out, model.to_json())
    print(f'wrote {out} (wall {data.wall_s:.0f} s); use it with [measurement] noise_model = "{out}"')
    if json_path is not None:
        write_json_atomic(json_path, {"model": model.to_json(), "report": report, "rows": list(data.rows)})
        print(f"wrote {json_path}")
    return EXIT_OK


def offset_lines(model: NoiseModel) -> list[str]:
    """What ``bve-mj calibrate`` says of the fruit's own centre offset in ``model``."""
    h, v = model.centre_bias_rel
    lines = [
        f"the fruit's own centre offset: σ {100 * h:.2f}% of its radius horizontally, {100 * v:.2f}% "
        "vertically over all fruits (added to the centre's covariance where the neighbours are not known)"
    ]
    if model.centre_offset_terms:
        names = ("1", "(k-1)²", "n̄²")
        terms = " + ".join(f"{c:.3g}·{n}" for c, n in zip(model.centre_offset_terms, names, strict=True))
        lines.append(
            f"  by the fruit: variance [share of radius²] = {terms} (k the fruit type's shape index, n̄ the "
            "mean neighbour share of the views fused)"
        )
    return lines
