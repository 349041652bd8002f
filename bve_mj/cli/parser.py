"""The ``bve-mj`` argument parser: every command, option and default."""

from __future__ import annotations

import argparse

from bve_mj.cli.args import Parser, one_of, version_text
from bve_mj.config.experiments import EXPERIMENTS
from bve_mj.config.fields import (
    DetectorKind,
    FilterKind,
    Formulation,
    FruitsMode,
    MeasurementKind,
    OptimiserName,
    PlannerKind,
    PlanningModel,
    RobotName,
    StateKind,
    WorldName,
)

__all__ = ["build_parser"]

ALL_EXPERIMENTS = ",".join(EXPERIMENTS)


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(prog="bve-mj", description="Active monocular 3D fruit localisation: BVE + EKF.")
    parser.add_argument("--version", action="version", version=f"bve-mj {version_text()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=Parser)
    paper = sub.add_parser(
        "paper",
        help="the paper's synthetic protocol, E1-E10, table like the paper's with its numbers beside ours",
        description="Reproduce the paper's table in the synthetic world (Gaussian measurements).",
    )
    paper.add_argument(
        "--experiments",
        default=ALL_EXPERIMENTS,
        help="comma-separated, e.g. E1,E6",
    )
    paper.add_argument("--runs", default="100", help="runs per experiment (default 100)")
    paper.add_argument("--seed", default="0", help="base seed (default 0)")
    paper.add_argument("--steps", default=None, help="planned views per run (default from settings: 30)")
    paper.add_argument(
        "--measurement", default=None, help="range (the paper's EKF) or camera (default from settings: range)"
    )
    paper.add_argument("--planner", default=None, help=one_of(PlannerKind))
    paper.add_argument("--filter", default=None, help=f"{one_of(FilterKind)} (default from settings: ekf)")
    paper.add_argument("--planning-model", default=None, help=one_of(PlanningModel))
    paper.add_argument("--optimiser", default=None, help=one_of(OptimiserName))
    paper.add_argument("--robot", default=None, help=f"arm for E5/E10: {one_of(RobotName)}")
    paper.add_argument("--joint-limits", default=None, help="urdf, or emanual (manipulator_h only)")
    paper.add_argument("--formulation", default=None, help=f"kinematic feasibility: {one_of(Formulation)}")
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
    ep.add_argument("--planner", default=None, help=one_of(PlannerKind))
    ep.add_argument("--filter", default=None, help=f"{one_of(FilterKind)} (default from settings: ekf)")
    ep.add_argument(
        "--detector", default=None, help=f"{one_of(DetectorKind)} (default from settings: builtin)"
    )
    ep.add_argument(
        "--state",
        default=None,
        help="centre (the paper's: range from the size with the prior's radius) or centre_radius "
        "(the radius estimated too; default here)",
    )
    ep.add_argument("--planning-model", default=None, help=one_of(PlanningModel))
    ep.add_argument("--robot", default=None, help=one_of(RobotName))
    ep.add_argument(
        "--fruits",
        default=None,
        help=f"{one_of(FruitsMode)}: the target fruit (default), or every ripe fruit of the truss",
    )
    ep.add_argument("--approach", action="store_true", help="approach mode: end close to the fruit")
    ep.add_argument(
        "--pick",
        default=None,
        metavar="ROUNDS",
        help="with --fruits all: the harvest picks each fruit it reaches and the survey goes on for the "
        "fruit the picked ones hid, up to ROUNDS times (0-10; implies --approach; tracking.pick_rounds)",
    )
    ep.add_argument("--realistic", action="store_true", help="sensor realism on (noise, calibration error)")
    ep.add_argument("--video", default=None, help="write an mp4 of the approach path here")
    ep.add_argument(
        "--viewer",
        action="store_true",
        help="play the episode live in MuJoCo's viewer (needs a display; one target, not with --video)",
    )
    ep.add_argument("--plots", default=None, help="write PREFIX_path.png and PREFIX_error.png")
    ep.add_argument("--json", default=None, help="write the episode log (settings, views, outcome) here")
    ep.add_argument("--quiet", action="store_true", help="print only the summary")
    ep.add_argument(
        "--initial-error",
        default=None,
        help="prior error half-width e [m]: along the ray (episode.prior = detection) or per axis "
        "(cube); a fruit localised beyond it is not the target (ambiguous); default 0.05",
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
            default="E1,E5,E6,E10" if recover else ALL_EXPERIMENTS,
            help="comma-separated, e.g. E1,E6",
        )
        c.add_argument(
            "--worlds",
            default="synthetic",
            help=f"{one_of(WorldName, last=', ')} or {one_of(WorldName, ',', ',')}",
        )
        c.add_argument("--planners", default="bve", help=f"any of {one_of(PlannerKind, ',', ',')}")
        c.add_argument(
            "--measurements",
            default=None,
            help=f"{one_of(MeasurementKind, ',', ',')} (default: each world's measurement.kind from the "
            "settings; auto = range in the synthetic world, camera in MuJoCo)",
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
        "--measurement",
        default=None,
        help=f"{one_of(MeasurementKind)} for every scenario (default: each file's)",
    )
    sc.add_argument(
        "--filter", default=None, help=f"{one_of(FilterKind)} for every scenario (default: each file's)"
    )
    sc.add_argument(
        "--state", default=None, help=f"{one_of(StateKind)} for every scenario (default: each file's)"
    )
    sc.add_argument(
        "--fruits",
        default=None,
        help=f"{one_of(FruitsMode)}: localise the target (default) or every ripe fruit of each scene",
    )
    sc.add_argument(
        "--planners",
        default=None,
        help=f"with --fruits all: any of {one_of(PlannerKind, ',', ',')} on the same seeds, compared "
        "with the first (default: each file's planner)",
    )
    sc.add_argument(
        "--pick",
        default=None,
        metavar="ROUNDS",
        help="with --fruits all: approach mode, and the harvest picks each fruit it reaches and surveys "
        "again for the fruit the picked ones hid, up to ROUNDS times (0-10; default: each file's)",
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
    cal.add_argument(
        "--drawn",
        default="0",
        help="also this many scene configurations drawn at random (bve-mj draw-scenes, the draw "
        "seeded by --seed), one scene of each (default 0)",
    )
    cal.add_argument("--views", default="25", help="views per scene (default 25)")
    cal.add_argument("--seed", default="1", help="base seed (default 1: not the suite's 0)")
    cal.add_argument("--workers", default=None, help="local processes (default: all cores)")
    cal.add_argument("--json", default=None, help="write every view's detection and error here")
    cal.add_argument(
        "--every-fruit",
        action="store_true",
        help="also measure the target's neighbours with the every-fruit detector (--fruits "
        "all): their errors fit the views' outlier tail the tracker fuses with (the model "
        "itself is the target's)",
    )
    cal.add_argument(
        "--twin-views",
        default="2",
        help="views per scene that also get twins from cameras 0-40 mm away: how the views from one "
        "place share their errors (a camera that holds learns nothing new); 0: none (default 2)",
    )
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
    res.add_argument("--experiments", default=ALL_EXPERIMENTS, help="comma-separated")
    res.add_argument("--scenario-seeds", default="20", help="episodes per scenario of the suite (default 20)")
    res.add_argument("--seed", default="0", help="base seed (default 0)")
    res.add_argument("--workers", default=None, help="local processes (default: all cores)")
    res.add_argument("--scheduler", default=None, help="Dask distributed scheduler address instead")
    res.add_argument("--quiet", action="store_true", help="no progress on stderr")
    scn = sub.add_parser(
        "scene",
        help="write the greenhouse of an episode (seed, settings) as an MJCF folder MuJoCo's viewer opens",
        description="Write the scene `bve-mj episode --seed S --config X` builds as DIR/scene.xml with its "
        "textures (python -m mujoco.viewer --mjcf=DIR/scene.xml opens it). DIR must be new, empty, or "
        "hold a scene this command wrote (which is replaced); nothing else in it is overwritten.",
    )
    scn.add_argument("--seed", default="0", metavar="S", help="the episode's seed (default 0)")
    scn.add_argument(
        "--config", default=None, metavar="X.toml", help="scenario TOML (sections of bve_mj.config.Settings)"
    )
    scn.add_argument("--out", required=True, metavar="DIR", help="the folder to write (created)")
    drw = sub.add_parser(
        "draw-scenes",
        help="write scenario files of greenhouse configurations drawn at random (scenes nobody tuned for)",
        description="Draw COUNT configurations (fruit type, truss, ripeness, leaves, light, flash, "
        "sensor) from the scene space of bve_mj.campaigns.drawn_scenes and write each as a scenario "
        "file DIR/drawn_SEED_I.toml: bve-mj scenarios --dir DIR runs them. The same seed writes the "
        "same files; a file already there is never overwritten.",
    )
    drw.add_argument("--count", default="20", metavar="N", help="configurations to draw (default 20)")
    drw.add_argument("--seed", default="0", metavar="S", help="the draw's seed (default 0)")
    drw.add_argument("--out", required=True, metavar="DIR", help="the folder to write them in (created)")
    return parser
