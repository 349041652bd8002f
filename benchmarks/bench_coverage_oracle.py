"""Whose miss is it: the ripe fruit an every-fruit episode leaves unlocalised, and whether the
detector measures them from any view the arm can take at all.

    python benchmarks/bench_coverage_oracle.py [--scenario truss_cluster[,ripe_truss,...]]
                                               [--episodes 5] [--seed 3141] [--views 30]
                                               [--picked] [--quiet]

For each episode (seeded as the suite seeds it): the every-fruit episode itself (which ripe
fruit of the work zone it localised within 5 mm), then, in the same scene, ``--views``
look-at poses the arm reaches (IK), aimed in turn at each ripe fruit of the zone from
0.15-0.40 m, azimuth within 70° of the robot's side, elevation -35° to 55° (the calibration's
pose sampler). In each view the every-fruit detector (``--fruits all``) runs on the rendered
image; a detection or refusal is matched to the ripe fruit whose projected centre lies
within half its apparent radius. Per ripe fruit: the views that measured it, those where 5
or more of 9 rays from the camera to its face reach it (``visible_share`` >= 0.55: mostly
in view), and why the views that found but refused it did so.

A fruit the episode missed but these views measure in two or more is the planner's (or the
tracker's) miss; one no view measures, though mostly in view in many, is the detector's.

``--picked``: the views are taken with the fruit the episode localised taken off the plant
(:class:`bve_mj.sim.basket.Basket`, as ``tracking.pick_rounds`` has the harvest do): what a
survey after the harvest could measure of the fruit they hid.
"""

from __future__ import annotations

import math
import re
from collections import Counter
from dataclasses import dataclass, field

import mujoco
import numpy as np

from bve_mj.campaigns.calibration import fruit_images, matched_fruit
from bve_mj.campaigns.scenarios import load_suite
from bve_mj.campaigns.spec import episode_seed
from bve_mj.cli.script import SEED, ScriptParser, guarded, integer
from bve_mj.config import Settings, with_overrides
from bve_mj.errors import BveError
from bve_mj.loop.mujoco import episode_settings
from bve_mj.loop.mujoco_fruits import ripe_fruit_in_zone, run_every_fruit_episode
from bve_mj.loop.start import start_episode
from bve_mj.perception.all_fruit import detect_all
from bve_mj.perception.detection import Intrinsics
from bve_mj.robot import IkOptions, look_at_ik
from bve_mj.sim.arm import CAMERA_NAME
from bve_mj.sim.basket import Basket
from bve_mj.sim.mujoco_world import declared_noise
from bve_mj.sim.render import OffscreenRenderer
from bve_mj.sim.scene_model import fruit_geom_name
from bve_mj.sim.true_boxes import visible_share
from bve_mj.threads import one_blas_thread

MOSTLY_VISIBLE = 0.55  # 5 of 9 rays


@dataclass
class FruitSeen:
    """What the sampled views made of one ripe fruit."""

    localised: bool
    measured: int = 0
    mostly_visible: int = 0
    refusals: Counter[str] = field(default_factory=Counter)


def _reason(text: str) -> str:
    """A refusal's reason without its numbers ("only 110 deg of ..." -> "only N deg of ...")."""
    return re.sub(r"\d+(\.\d+)?", "N", text.split(":")[0])[:48]


def oracle_episode(settings: Settings, seed: int, views: int, picked: bool = False) -> list[FruitSeen]:
    """The episode's localised ripe fruit and what ``views`` sampled views make of them
    (``picked``: with the fruit it localised taken off the plant)."""
    ep = run_every_fruit_episode(settings, seed)
    matches, _, _ = ep.matches()
    localised = {m.fruit.name: m.localised_within(5.0) for m in matches}
    search = episode_settings(with_overrides(settings, episode={"approach": False}))
    start = start_episode(search, seed)
    ripe = ripe_fruit_in_zone(start.info, search, start.prior.centre_m)
    seen = [FruitSeen(localised.get(fr.name, False)) for fr in ripe]
    if not ripe or start.q_start is None:
        return seen
    model, kin, cam = start.model, start.kin, search.camera
    data = mujoco.MjData(model)
    adr = np.array([model.jnt_qposadr[model.joint(j).id] for j in kin.joint_names])
    intr = Intrinsics.from_camera(cam)
    measurement, fruit = declared_noise(search)
    renderer = OffscreenRenderer(
        model, cam.width_px, cam.height_px, shadows=search.scene.shadows, blur_sigma_px=cam.blur_sigma_px
    )
    rng = np.random.default_rng(seed)
    q = start.q_start
    taken = attempts = 0
    basket = Basket(model, start.info)
    if picked:
        for fr in ripe:
            if localised.get(fr.name, False):
                basket.take(fr.name)
    try:
        while taken < views and attempts < 8 * views:
            attempts += 1
            aimed = ripe[attempts % len(ripe)].centre_m
            az, el = math.radians(rng.uniform(-70.0, 70.0)), math.radians(rng.uniform(-35.0, 55.0))
            d = np.array([-math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
            p_want = aimed + rng.uniform(0.15, 0.40) * d
            ik = look_at_ik(kin, p_want, aimed, q, rng, IkOptions(restarts=2, upright=True))
            if not ik.success:
                continue
            taken += 1
            q = ik.q
            data.qpos[adr] = q
            mujoco.mj_forward(model, data)
            image = renderer.render(data, CAMERA_NAME)
            p, R = kin.camera_pose(q)
            for s, fr in zip(seen, ripe, strict=True):
                t = R.T @ (fr.centre_m - p)
                u, v = intr.project(t) if t[0] > fr.radius_m else (-1.0, -1.0)
                if 0 <= u < cam.width_px and 0 <= v < cam.height_px:
                    share = visible_share(model, data, p, fr.centre_m, fr.radius_m, fruit_geom_name(fr.name))
                    s.mostly_visible += share >= MOSTLY_VISIBLE
            found = detect_all(
                image, intr, fruit, measurement, search.detector,
                up_camera=R.T[:, 2], max_range_m=search.tracking.max_range_m,
            )  # fmt: skip
            measured = set()
            images = fruit_images(ripe, p, R, intr)
            for det in found.detections:
                m = matched_fruit(det.centre_px, images)
                if m is not None and m.fruit_index not in measured:
                    seen[m.fruit_index].measured += 1
                    measured.add(m.fruit_index)
            for ref in found.refused:
                m = None if ref.centre_px is None else matched_fruit(ref.centre_px, images)
                if m is not None and m.fruit_index not in measured:
                    seen[m.fruit_index].refusals[_reason(ref.reason)] += 1
    finally:
        basket.put_back()  # the compiled scene is shared by the process's episodes
        renderer.close()
    return seen


def main() -> None:
    ap = ScriptParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="truss_cluster")
    ap.add_argument("--episodes", type=integer(1), default=5)
    ap.add_argument("--seed", type=SEED, default=3141)
    ap.add_argument("--views", type=integer(1), default=30, help="sampled views per scene")
    ap.add_argument("--picked", action="store_true", help="views with the fruit the episode localised picked")
    ap.add_argument("--quiet", action="store_true", help="only the summary per scenario")
    args = ap.parse_args()
    try:
        suite = load_suite(only=args.scenario.split(","))
    except BveError as exc:
        ap.error(f"--scenario: {exc}")
    lines = []
    with one_blas_thread():
        for sc in suite:
            base = sc.settings("camera", None, "centre_radius")
            settings = with_overrides(base, tracking={"fruits": "all"})
            every: list[FruitSeen] = []
            for run in range(args.episodes):
                seen = oracle_episode(settings, episode_seed(args.seed, run), args.views, args.picked)
                every += seen
                if not args.quiet:
                    row = " ".join(
                        f"{'L' if s.localised else '-'}{s.measured}/{s.mostly_visible}" for s in seen
                    )
                    print(f"{sc.name} episode {run}: localised?measured/mostly-visible per ripe fruit: {row}",
                          flush=True)  # fmt: skip
            missed = [s for s in every if not s.localised]
            reasons = sum((s.refusals for s in missed), Counter())
            n = max(len(every), 1)
            found = sum(s.localised for s in every)
            lines.append(
                f"{sc.name}{' (the localised picked)' if args.picked else ''}: {len(every)} ripe fruit, "
                f"localised by the episode {found} "
                f"({100 * found / n:.0f}%), measured in >= 2 of {args.views} "
                f"sampled views {sum(s.measured >= 2 for s in every)} "
                f"({100 * sum(s.measured >= 2 for s in every) / n:.0f}%); of the {len(missed)} missed: "
                f"measured in >= 2 views {sum(s.measured >= 2 for s in missed)}, never measured "
                f"{sum(s.measured == 0 for s in missed)} (mostly in view in a median of "
                f"{np.median([s.mostly_visible for s in missed]) if missed else 0:.0f} views); "
                f"refusals of the missed: {', '.join(f'{r} x{c}' for r, c in reasons.most_common(4))}"
            )
            print(lines[-1], flush=True)
    if len(lines) > 1:
        print("\n".join(lines))


if __name__ == "__main__":
    guarded(main)
