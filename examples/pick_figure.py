"""A fruit at the back of a cluster, before and after the harvest picked the ones in front.

    python examples/pick_figure.py [EPISODE_SEED] [OUT_DIR]

Runs the every-fruit survey of the suite's ``truss_cluster`` (episode seed, default 9105),
takes the ripe fruit of the work zone it did not localise that is most hidden seen from the
aisle, and puts the arm's eye-in-hand camera at the distance band straight in front of it
(look-at IK). The image there is run through the every-fruit detector twice: with the
cluster as it grows (left), and with the fruit the survey localised picked
(:meth:`bve_mj.sim.mujoco_world.MujocoWorld.pick`: each fruit and its calyx leave the scene,
as ``tracking.pick_rounds`` has the harvest do). Writes OUT_DIR/pick.png (default OUT_DIR:
out/, which git ignores). White: the hidden fruit's true silhouette; green: the other ripe
fruit; magenta: the detector's measured fruit. Prints what the detector made of the hidden
fruit in each image.
"""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np

from bve_mj.campaigns.scenarios import load_suite
from bve_mj.cli.script import SEED, ScriptParser, folder, guarded
from bve_mj.config import with_overrides
from bve_mj.estimation.visibility import outline_shown_deg
from bve_mj.loop.mujoco import episode_settings
from bve_mj.loop.mujoco_fruits import run_every_fruit_episode
from bve_mj.loop.start import start_episode
from bve_mj.perception.all_fruit import detect_all
from bve_mj.perception.detection import Intrinsics
from bve_mj.reporting.detector_panel import detector_panel, write_side_by_side
from bve_mj.robot import IkOptions, look_at_ik
from bve_mj.sim.arm import CAMERA_NAME
from bve_mj.sim.mujoco_world import MujocoWorld


def main(seed: int = 9105, out_dir: str = "out") -> None:
    (scenario,) = load_suite(only=["truss_cluster"])
    every = with_overrides(scenario.settings(), tracking={"fruits": "all"})
    survey = run_every_fruit_episode(every, seed)
    matches, _, _ = survey.matches()
    taken = [m.fruit for m in matches if m.localised_within(5.0)]
    missed = [m.fruit for m in matches if not m.localised_within(5.0)]
    if not taken or not missed:
        localised = f"the survey localised {len(taken)} of {len(matches)} ripe fruit"
        raise SystemExit(f"episode seed {seed}: {localised}: none hidden behind the others to show")
    s = episode_settings(every)
    start = start_episode(s, seed)
    assert start.q_start is not None  # the survey ran: the arm has a ready pose
    cam = s.camera
    ripe = [m.fruit for m in matches]
    centres = np.array([f.centre_m for f in ripe])
    radii = np.array([f.radius_m for f in ripe])
    aisle = [c + s.band_distance_m * np.array([-1.0, 0.0, 0.0]) for c in centres]
    k = min(
        (ripe.index(f) for f in missed),
        key=lambda i: outline_shown_deg(
            i, centres, radii, aisle[i][None], cam.focal_px, cam.width_px, cam.height_px, rims=True
        )[0],
    )
    rng = np.random.default_rng(seed)
    ik = look_at_ik(start.kin, aisle[k], centres[k], start.q_start, rng, IkOptions(upright=True))
    if not ik.success:
        raise SystemExit(f"the arm reaches no aisle view of {ripe[k].name}")
    world = MujocoWorld(s, start.kin, start.model, start.info, ik.q, centres[k], rng)
    intr = Intrinsics.from_camera(cam)
    panels, lines = [], []
    try:
        for title in ("as it grows", "front fruit picked"):
            if title != "as it grows":
                for fruit in taken:
                    world.pick(fruit.name)
            mujoco.mj_forward(world.model, world.data)
            image = world.renderer.render(world.data, CAMERA_NAME)
            p, R = start.kin.camera_pose(ik.q)
            found = detect_all(
                image, intr, world.fruit_prior, world.measurement, s.detector,
                up_camera=R.T[:, 2], max_range_m=s.tracking.max_range_m,
            )  # fmt: skip
            here = [f for f in ripe if f.name not in world.picked]
            shown, verdict = detector_panel(image, here, here.index(ripe[k]), found, p, R, intr, title)
            panels.append(shown)
            lines.append(f"  {title}: {verdict}")
    finally:
        world.close()
    written = write_side_by_side(panels, Path(out_dir) / "pick.png")
    names = ", ".join(f.name for f in taken)
    print(f"truss_cluster episode seed {seed}: the survey localised {len(taken)} of {len(ripe)}: {names}")
    where = np.round(centres[k], 3).tolist()
    print(f"{ripe[k].name} at {where} m, seen from the aisle at {s.band_distance_m:.2f} m:")
    print("\n".join(lines))
    print(f"wrote {written} (as it grows | front fruit picked)")


if __name__ == "__main__":
    ap = ScriptParser(description=__doc__.splitlines()[0])
    ap.add_argument("seed", nargs="?", type=SEED, default=9105, help="the episode's seed")
    ap.add_argument("out_dir", nargs="?", type=folder, default="out")
    args = ap.parse_args()
    guarded(lambda: main(args.seed, args.out_dir))
