"""The harvest over seeds: every visit reached, and none touching a fruit.

    python benchmarks/bench_harvest.py [--scenario ripe_truss[,truss_chain,...]] [--episodes 10]
                                       [--seed 4242] [--planner bve] [--quiet]

Runs ``bve-mj episode --fruits all --approach`` episodes of each suite scenario (episode ``i``
seeded as the suite seeds it) and prints per episode each visit (track, reached, least
distance between the arm and any fruit during the moves [mm]; at most 50 mm is measured) and
the least distance during the views before the harvest (the planner's moves: ``--planner``
bve, or a baseline: random, circle, fixed), then per scenario the count of visits, reached, touching a
fruit (least distance <= 0), and episodes whose views touched one.
Target (issue 14): every ripe fruit visited within 0.1 m, never touching any fruit.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import get_args

import numpy as np

from bve_mj.campaigns.scenarios import load_suite
from bve_mj.campaigns.spec import episode_seed
from bve_mj.cli.script import SEED, ScriptParser, guarded, integer
from bve_mj.config import PlannerKind, with_overrides
from bve_mj.errors import BveError
from bve_mj.loop.arm_clearance import FruitClearance
from bve_mj.loop.fruit_records import FruitsView
from bve_mj.loop.harvest import Visit
from bve_mj.loop.mujoco_fruits import run_every_fruit_episode
from bve_mj.sim.mujoco_world import MujocoWorld
from bve_mj.sim.scene_model import Fruit


class ViewsClearance:
    """An episode recorder that records nothing but the least distance between the arm and
    any fruit during the views (until the harvest's order is told)."""

    def __init__(self) -> None:
        self.clearance: FruitClearance | None = None
        self.harvesting = False

    @property
    def least_m(self) -> float:
        return math.inf if self.clearance is None else self.clearance.least_m

    def attach(self, world: MujocoWorld, ripe: Sequence[Fruit], zone_centre_m: np.ndarray) -> None:
        self.clearance = FruitClearance(world, world.info)

    def on_view(self, view: FruitsView) -> None:
        pass

    def on_step(self, sim_time: float) -> None:
        if self.clearance is not None and not self.harvesting:
            self.clearance.step(sim_time)

    def on_order(self, order: Sequence[int]) -> None:
        self.harvesting = True

    def on_visit(self, track: int) -> None:
        pass

    def on_visited(self, visit: Visit) -> None:
        pass


def _reached(visit: Visit) -> str:
    return "ok" if visit.reached else "no"


def main() -> None:
    ap = ScriptParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="ripe_truss")
    ap.add_argument("--episodes", type=integer(1), default=10)
    ap.add_argument("--seed", type=SEED, default=4242)
    ap.add_argument("--planner", default="bve", choices=get_args(PlannerKind), help="the views' planner")
    ap.add_argument("--quiet", action="store_true", help="only the count per scenario")
    args = ap.parse_args()
    try:
        suite = load_suite(only=args.scenario.split(","))
    except BveError as exc:
        ap.error(f"--scenario: {exc}")
    lines = []
    for sc in suite:
        base = sc.settings("camera", None, "centre_radius")
        settings = with_overrides(
            base, tracking={"fruits": "all"}, episode={"approach": True}, planner={"kind": args.planner}
        )
        visits = reached = touched = views_touched = 0
        for run in range(args.episodes):
            views = ViewsClearance()
            ep = run_every_fruit_episode(settings, episode_seed(args.seed, run), views)
            done = () if ep.harvest is None else ep.harvest.visits
            visits += len(done)
            reached += sum(v.reached for v in done)
            touched += sum(v.clearance_m <= 0.0 for v in done)
            views_touched += views.least_m <= 0.0
            row = ", ".join(f"#{v.track} {_reached(v)} {1e3 * v.clearance_m:.1f}" for v in done)
            if not args.quiet:
                print(
                    f"{sc.name} episode {run}: {ep.result.outcome}; views {1e3 * views.least_m:.1f}; "
                    f"visits: {row}",
                    flush=True,
                )
        lines.append(
            f"{sc.name}: {visits} visits, reached {reached}, touching a fruit {touched}; "
            f"episodes whose views touched a fruit {views_touched} of {args.episodes}"
        )
        print(lines[-1], flush=True)
    if len(lines) > 1:
        print("\n".join(lines))


if __name__ == "__main__":
    guarded(main)
