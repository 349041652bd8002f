"""A fruit at the back of a cluster: the view from the aisle, and the view that shows it.

    python examples/unhide_figure.py [EPISODE_SEED] [OUT_DIR]

Builds the every-fruit episode scene of the suite's ``truss_cluster`` (episode seed, default
3669142227), takes the ripe fruit of the work zone that is most hidden seen from the aisle
side (the camera at the distance band straight in front of it), and ranks the positions
within a generous step of that camera by the outline the true fruit predict it shows there
(:func:`bve_mj.planning.unhide.unhiding_positions`, as the planner ranks them from its
tracks). Both views are taken with the arm's eye-in-hand camera (look-at IK) and run
through the every-fruit detector. Writes OUT_DIR/unhide.png (default OUT_DIR: out/, which
git ignores): the aisle view (left) and the unhiding view (right). White: the hidden fruit's
true silhouette; green: the other ripe fruit; magenta: the detector's measured fruit.
Prints what the detector made of the hidden fruit in each view.
"""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np

from bve_mj.campaigns.scenarios import load_suite
from bve_mj.cli.script import SEED, ScriptParser, folder, guarded
from bve_mj.config import with_overrides
from bve_mj.estimation.visibility import outline_shown_deg
from bve_mj.loop.mujoco import episode_constraints, episode_settings
from bve_mj.loop.mujoco_fruits import ripe_fruit_in_zone
from bve_mj.loop.start import start_episode
from bve_mj.perception.all_fruit import detect_all
from bve_mj.perception.detection import Intrinsics
from bve_mj.planning.constraints import build_constraints
from bve_mj.planning.unhide import unhiding_positions
from bve_mj.reporting.detector_panel import detector_panel, write_side_by_side
from bve_mj.robot import IkOptions, look_at_ik
from bve_mj.sim.arm import CAMERA_NAME
from bve_mj.sim.mujoco_world import declared_noise
from bve_mj.sim.render import OffscreenRenderer


def main(seed: int = 3669142227, out_dir: str = "out") -> None:
    (scenario,) = load_suite(only=["truss_cluster"])
    s = episode_settings(with_overrides(scenario.settings(), tracking={"fruits": "all"}))
    start = start_episode(s, seed)
    if start.q_start is None:
        raise SystemExit(f"episode seed {seed}: the arm reaches no ready pose in this scene")
    ripe = ripe_fruit_in_zone(start.info, s, start.prior.centre_m)
    centres = np.array([f.centre_m for f in ripe])
    radii = np.array([f.radius_m for f in ripe])
    cam, f = s.camera, s.camera.focal_px

    def shown(i: int, c: np.ndarray, r: np.ndarray, positions: np.ndarray) -> np.ndarray:
        return outline_shown_deg(i, c, r, positions, f, cam.width_px, cam.height_px, rims=True)

    aisle = [centres[i] + s.band_distance_m * np.array([-1.0, 0.0, 0.0]) for i in range(len(ripe))]
    arcs = [float(shown(i, centres, radii, aisle[i][None])[0]) for i in range(len(ripe))]
    k = int(np.argmin(arcs))
    rng = np.random.default_rng(seed)
    constraints = build_constraints(episode_constraints(s), s, centres[k])
    ranked = unhiding_positions(
        k, centres, radii, aisle[k], constraints, 0.25, s.band_distance_m, shown, s.detector.min_arc_deg, rng
    )
    model, kin = start.model, start.kin
    data = mujoco.MjData(model)
    adr = np.array([model.jnt_qposadr[model.joint(j).id] for j in kin.joint_names])
    intr = Intrinsics.from_camera(cam)
    measurement, fruit = declared_noise(s)
    renderer = OffscreenRenderer(model, cam.width_px, cam.height_px, blur_sigma_px=cam.blur_sigma_px)
    panels, lines = [], []
    q0 = start.q_start
    try:
        for title, options in (("aisle", [(aisle[k], arcs[k])]), ("unhiding", ranked)):
            options_ik = IkOptions(upright=True)
            reached = next(
                (
                    (ik, a)
                    for p_want, a in options
                    if (ik := look_at_ik(kin, p_want, centres[k], q0, rng, options_ik)).success
                ),
                None,
            )
            if reached is None:
                raise SystemExit(f"the arm reaches no {title} view of {ripe[k].name}")
            ik, predicted = reached
            data.qpos[adr] = ik.q
            mujoco.mj_forward(model, data)
            image = renderer.render(data, CAMERA_NAME)
            p, R = kin.camera_pose(ik.q)
            found = detect_all(
                image, intr, fruit, measurement, s.detector,
                up_camera=R.T[:, 2], max_range_m=s.tracking.max_range_m,
            )  # fmt: skip
            shown_bgr, verdict = detector_panel(image, ripe, k, found, p, R, intr, title)
            panels.append(shown_bgr)
            where = np.round(p, 3).tolist()
            lines.append(f"  {title}: camera {where} m, outline predicted {predicted:.0f} deg; {verdict}")
    finally:
        renderer.close()
    written = write_side_by_side(panels, Path(out_dir) / "unhide.png")
    print(f"truss_cluster episode seed {seed}: {ripe[k].name} at {np.round(centres[k], 3).tolist()} m")
    print("\n".join(lines))
    print(f"wrote {written} (aisle | unhiding)")


if __name__ == "__main__":
    ap = ScriptParser(description=__doc__.splitlines()[0])
    ap.add_argument("seed", nargs="?", type=SEED, default=3669142227, help="the episode's seed")
    ap.add_argument("out_dir", nargs="?", type=folder, default="out")
    args = ap.parse_args()
    guarded(lambda: main(args.seed, args.out_dir))
