"""How far off the circle of a fruit seen only in part is: the noise of the weak sightings.

    python benchmarks/bench_unmeasured.py [--seed 8642] [--episodes 20]
        [--only ripe_truss,truss_chain,truss_cluster,cherry_truss,plant_trusses]

Runs every-fruit episodes of the suite's truss scenarios (episode ``i`` seeded as the suite
seeds it) and, in every view, compares each refusal of a fruit seen in part (too little of its
outline, or too loose a fit: ``Refusal.partial``) with the true fruit whose image it lies on
(its centre within one true apparent radius of the truth's image): the centre's error per
image coordinate and the radius' relative error, both as shares of the true apparent radius.
Prints their rms, median and percentiles beside the constants the loop uses
(``bve_mj.estimation.unmeasured.CENTRE_SIGMA_REL`` and ``RADIUS_SIGMA_REL``, which the rms of
seed 8642, 20 episodes, set); then the same errors by the circle's size against the truth's,
with the share the loop drops as fragments (``bve_mj.estimation.unmeasured.too_small``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from bve_mj.campaigns.scenarios import load_suite
from bve_mj.campaigns.spec import episode_seed
from bve_mj.cli.script import SEED, ScriptParser, guarded, integer
from bve_mj.config import with_overrides
from bve_mj.estimation.assignment import Sighting
from bve_mj.estimation.models import BearingSizeModel
from bve_mj.estimation.unmeasured import CENTRE_SIGMA_REL, RADIUS_SIGMA_REL, too_small
from bve_mj.loop.fruit_records import FruitsView
from bve_mj.loop.mujoco_fruits import run_every_fruit_episode
from bve_mj.sim.scene_model import Fruit


class _Refusals:
    """A recorder that keeps, per view, the partial refusals and the true camera pose."""

    def __init__(self) -> None:
        self.world: Any = None
        self.zone_centre_m = np.zeros(3)
        self.centre_err: list[np.ndarray] = []
        self.radius_err: list[float] = []
        self.fragment: list[bool] = []

    def attach(self, world: Any, ripe: Sequence[Fruit], zone_centre_m: np.ndarray) -> None:
        self.world = world
        self.zone_centre_m = np.asarray(zone_centre_m, dtype=float)

    def on_step(self, sim_time: float) -> None:
        pass

    def on_order(self, order: Sequence[int]) -> None:
        pass

    def on_visit(self, track: int) -> None:
        pass

    def on_visited(self, visit: Any) -> None:
        pass

    def on_view(self, view: FruitsView) -> None:
        w = self.world
        every = w.last.every
        if every is None:
            return
        p, R = w.kin.camera_pose(w.last.q)
        f = w.intrinsics.focal_px
        fruit, zone_m = w.settings.fruit, w.settings.tracking.zone_m
        r_min = fruit.radius_m * (1.0 - fruit.radius_spread_rel)  # as the loop: r0 - √3·σ of ±spread
        truth = []
        for fr in w.info.fruits:
            t = R.T @ (fr.centre_m - p)
            if t[0] > 0.02:
                truth.append((w.intrinsics.project(t), f * fr.radius_m / float(np.linalg.norm(t))))
        for r in every.refused:
            if not r.partial or r.centre_px is None or not truth:
                continue
            uv, r_px = min(truth, key=lambda x: float(np.linalg.norm(r.centre_px - x[0])) / x[1])
            if np.linalg.norm(r.centre_px - uv) < r_px:
                self.centre_err.append((r.centre_px - uv) / r_px)
                self.radius_err.append(r.radius_px / r_px - 1.0)
                alpha = math.atan(r.radius_px / f)
                weak = Sighting(np.array([0.0, 0.0, alpha]), BearingSizeModel(p, R, np.eye(3)))
                self.fragment.append(too_small(weak, self.zone_centre_m, zone_m, r_min))


def main() -> None:
    ap = ScriptParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=SEED, default=8642)
    ap.add_argument("--episodes", type=integer(1), default=20)
    ap.add_argument("--only", default="ripe_truss,truss_chain,truss_cluster,cherry_truss,plant_trusses")
    args = ap.parse_args()
    rec = _Refusals()
    for sc in load_suite(only=args.only.split(",")):
        settings = with_overrides(sc.settings("camera", None, "centre_radius"), tracking={"fruits": "all"})
        for run in range(args.episodes):
            run_every_fruit_episode(settings, episode_seed(args.seed, run), rec)
        print(f"{sc.name}: {len(rec.radius_err)} partial refusals on a true fruit so far", flush=True)
    c = np.array(rec.centre_err).reshape(-1, 2)
    r = np.array(rec.radius_err)
    rms_c, med_c = np.sqrt(np.mean(c**2, axis=0)).round(3), np.median(np.abs(c), axis=0).round(3)
    print(f"centre error / true apparent radius: rms (u, v) {rms_c}, median |.| {med_c}; "
          f"the loop uses {CENTRE_SIGMA_REL}")  # fmt: skip
    print(f"radius relative error: rms {np.sqrt(np.mean(r**2)):.3f}, percentiles 5/25/50/75/95 "
          f"{np.percentile(r, [5, 25, 50, 75, 95]).round(3)}; the loop uses {RADIUS_SIGMA_REL}")  # fmt: skip
    ratio, frag = r + 1.0, np.array(rec.fragment)
    d = np.linalg.norm(c, axis=1)
    print(
        "by the circle's radius / the truth's: n, centre error rms / the true radius, "
        "/ its own radius, dropped as fragments"
    )
    for lo, hi in ((0.0, 0.25), (0.25, 0.5), (0.5, 0.8), (0.8, np.inf)):
        m = (ratio >= lo) & (ratio < hi)
        if m.any():
            own = np.sqrt(np.mean((d[m] / ratio[m]) ** 2))
            print(f"  [{lo:.2f}, {hi:.2f}): {m.sum():5d}  {np.sqrt(np.mean(d[m] ** 2)):.2f}  {own:.2f}  "
                  f"{100 * frag[m].mean():.0f}%")  # fmt: skip


if __name__ == "__main__":
    guarded(main)
