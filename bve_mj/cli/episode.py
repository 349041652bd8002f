"""``bve-mj episode``: one closed-loop MuJoCo episode, its table, JSON, plots and video."""

from __future__ import annotations

import argparse
import dataclasses
import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from bve_mj.atomic import write_json_atomic
from bve_mj.cli.args import EXIT_NOT_LOCALISED, EXIT_OK, check_output_path, float_arg, given, int_arg
from bve_mj.loop.outcomes import Outcome

if TYPE_CHECKING:
    from bve_mj.config import Settings

__all__ = ["cmd_episode", "episode_cli_settings"]


def episode_cli_settings(args: argparse.Namespace) -> Settings:
    """``bve-mj episode``'s settings: the ``--config`` file (or the defaults), then the options
    given on the command line. :func:`bve_mj.loop.mujoco.run_mujoco_episode` resolves the
    closed loop's defaults, the same for the CLI and the Python API."""
    from typing import get_args

    from bve_mj.config import FruitsMode, SensorConfig, Settings, load_settings, with_overrides
    from bve_mj.errors import ConfigError

    fruits = getattr(args, "fruits", None)
    if fruits is not None and fruits not in get_args(FruitsMode):
        raise ConfigError("fruits", fruits, "one of " + ", ".join(get_args(FruitsMode)))
    pick = int_arg("pick", getattr(args, "pick", None), 0)
    if pick is not None and fruits != "all":
        raise ConfigError("pick", args.pick, "only with --fruits all")
    settings = load_settings(args.config) if args.config else Settings()
    settings = with_overrides(
        settings,
        episode=given(
            experiment=args.experiment,
            views=int_arg("views", args.views, 1),
            initial_error_m=float_arg("initial-error", args.initial_error, 0.0),
            approach=True if args.approach or pick else None,
        ),
        planner=given(kind=args.planner, planning_model=args.planning_model),
        measurement=given(kind=args.measurement),
        filter=given(kind=args.filter, state=args.state),
        detector=given(kind=getattr(args, "detector", None)),
        robot=given(name=args.robot),
        tracking=given(fruits=fruits, pick_rounds=pick),
    )
    if args.realistic:
        settings = dataclasses.replace(settings, sensor=SensorConfig.realistic())
    return settings


def cmd_episode(args: argparse.Namespace) -> int:
    from bve_mj.errors import ConfigError

    seed = int_arg("seed", args.seed, 0) or 0
    json_path = check_output_path("json", args.json)
    video_path = check_output_path("video", args.video)
    if video_path is not None and video_path.suffix.lower() != ".mp4":
        raise ConfigError("video", args.video, "a path ending in .mp4")
    plots_prefix = check_output_path("plots", args.plots)
    if plots_prefix is not None:
        from bve_mj.reporting.plots import require_matplotlib

        require_matplotlib("plots", args.plots)
    settings = episode_cli_settings(args)
    viewer = bool(getattr(args, "viewer", False))
    if viewer:
        if video_path is not None:
            raise ConfigError("viewer", "--viewer", "not with --video (one of them)")
        if settings.tracking.fruits == "all":
            raise ConfigError(
                "viewer", "--viewer", "not with --fruits all (the one-target episode's, for now)"
            )
        from bve_mj.reporting.live_viewer import require_display

        require_display()
    if settings.tracking.fruits == "all":
        from bve_mj.cli.fruits import run_every_fruit_cli

        if plots_prefix is not None:
            raise ConfigError("plots", args.plots, "not with --fruits all (the one-target episode's)")
        return run_every_fruit_cli(settings, seed, json_path, quiet=args.quiet, video_path=video_path)

    import numpy as np

    from bve_mj.loop.mujoco import Recorder, run_mujoco_episode
    from bve_mj.reporting.live_viewer import LiveViewer
    from bve_mj.reporting.video import EpisodeRecorder

    recorder: Recorder | None = None
    if video_path is not None:
        recorder = EpisodeRecorder(video_path)
    elif viewer:
        recorder = LiveViewer()
    try:
        result = run_mujoco_episode(settings, seed, recorder=recorder)
    finally:
        frames = recorder.close() if isinstance(recorder, EpisodeRecorder | LiveViewer) else 0
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
            claim = result.result.claim(rec)
            r, sd = claim.radius_m, claim.radius_sigma_m
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
                f"{true_range:6.3f} {v['error_mm']:8.2f} {1e3 * claim.sigma_max_m:7.2f} {radius:>14}"
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
    outcome = Outcome(doc["outcome"])
    if outcome.note is not None:
        print(outcome.note)
    disputed = result.standing_dispute()
    if disputed is not None and outcome.localised:
        print(
            f"view {disputed.iteration} disputed the estimate (NIS {disputed.nis:.1f}, beyond the noise "
            "model's 99.9%) and no view from another direction settled it: the estimate is an answer, "
            "not a claim that it is right"
        )
    if video_path is not None:
        print(f"wrote {video_path} ({frames} frames)")
    if plots_prefix is not None:
        from bve_mj.reporting.plots import plot_episode

        for p in plot_episode(doc, plots_prefix):
            print(f"wrote {p}")
    if json_path is not None:
        write_json_atomic(json_path, doc)
        print(f"wrote {json_path}")
    return EXIT_OK if outcome.localised else EXIT_NOT_LOCALISED


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
