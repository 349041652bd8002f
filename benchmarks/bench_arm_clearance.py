"""One-target episodes: does the arm touch a fruit?

    python benchmarks/bench_arm_clearance.py [--only clean,truss_chain,...] [--episodes 5]
                                             [--seed 7373] [--approach]

Runs ``bve-mj episode`` episodes of each suite scenario (episode ``i`` seeded as the suite
seeds it; ``--approach``: approach mode) with a recorder that measures, every few physics
steps, the least distance between the arm's geoms and every true fruit
(:class:`bve_mj.loop.arm_clearance.FruitClearance`), and prints per scenario the episodes that
touched a fruit (episode: least distance [mm]) and the outcomes, then the totals.
"""

from __future__ import annotations

from collections import Counter

from bve_mj.campaigns.scenarios import load_suite
from bve_mj.campaigns.spec import episode_seed
from bve_mj.cli.script import SEED, ScriptParser, guarded, integer
from bve_mj.config import with_overrides
from bve_mj.errors import BveError
from bve_mj.estimation.belief import Belief
from bve_mj.estimation.claim_shape import GAUSSIAN, ClaimShape
from bve_mj.loop.arm_clearance import FruitClearance
from bve_mj.loop.mujoco import run_mujoco_episode
from bve_mj.loop.records import ViewRecord
from bve_mj.sim.mujoco_world import MujocoWorld


class Clearance:
    """An episode recorder that records nothing but the arm's least distance to any fruit."""

    clearance: FruitClearance | None = None

    def attach(self, world: MujocoWorld, prior: Belief, shape: ClaimShape = GAUSSIAN) -> None:
        self.clearance = FruitClearance(world, world.info)

    def on_step(self, sim_time: float) -> None:
        if self.clearance is not None:
            self.clearance.step(sim_time)

    def on_view(self, record: ViewRecord) -> None:
        pass


def main() -> None:
    ap = ScriptParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default=None, help="comma-separated scenario names (default: all)")
    ap.add_argument("--episodes", type=integer(1), default=5)
    ap.add_argument("--seed", type=SEED, default=7373)
    ap.add_argument("--approach", action="store_true")
    args = ap.parse_args()
    try:
        suite = load_suite(only=None if args.only is None else args.only.split(","))
    except BveError as exc:
        ap.error(f"--only: {exc}")
    episodes = touched = 0
    outcomes: Counter[str] = Counter()
    for sc in suite:
        settings = sc.settings("camera", None, "centre_radius")
        if args.approach:
            settings = with_overrides(settings, episode={"approach": True})
        hits: list[str] = []
        scene_outcomes: Counter[str] = Counter()
        for run in range(args.episodes):
            recorder = Clearance()
            ep = run_mujoco_episode(settings, episode_seed(args.seed, run), recorder=recorder)
            least = recorder.clearance.least_m if recorder.clearance is not None else float("inf")
            scene_outcomes[str(ep.result.outcome)] += 1
            if least <= 0.0:
                hits.append(f"{run}: {1e3 * least:.1f}")
        episodes += args.episodes
        touched += len(hits)
        outcomes += scene_outcomes
        print(f"{sc.name}: touching {hits or 'none'}; {dict(scene_outcomes)}", flush=True)
    print(f"episodes {episodes}, touching a fruit {touched}; outcomes {dict(outcomes)}")


if __name__ == "__main__":
    guarded(main)
