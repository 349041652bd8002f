"""The harvest over seeds: every visit reached, and none touching a fruit.

    python benchmarks/bench_harvest.py [--scenario ripe_truss] [--episodes 10] [--seed 4242]

Runs ``bve-mj episode --fruits all --approach`` episodes of a suite scenario (episode ``i``
seeded as the suite seeds it) and prints per episode each visit (track, reached, least
distance between the arm and any fruit during the move [mm]; at most 50 mm is measured),
then the count of visits, reached, and touching a fruit (least distance <= 0).
Target (issue 14): every ripe fruit visited within 0.1 m, never touching any fruit.
"""

from __future__ import annotations

import argparse

from bve_mj.campaigns.scenarios import load_suite
from bve_mj.campaigns.spec import episode_seed
from bve_mj.config import with_overrides
from bve_mj.loop.mujoco_fruits import run_every_fruit_episode


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="ripe_truss")
    ap.add_argument("--episodes", type=int, default=10)
    ap.add_argument("--seed", type=int, default=4242)
    args = ap.parse_args()
    (sc,) = load_suite(only=[args.scenario])
    settings = with_overrides(
        sc.settings("camera", None, "centre_radius"), tracking={"fruits": "all"}, episode={"approach": True}
    )
    visits = reached = touched = 0
    for run in range(args.episodes):
        ep = run_every_fruit_episode(settings, episode_seed(args.seed, run))
        done = () if ep.harvest is None else ep.harvest.visits
        visits += len(done)
        reached += sum(v.reached for v in done)
        touched += sum(v.clearance_m <= 0.0 for v in done)
        row = ", ".join(f"#{v.track} {'ok' if v.reached else 'no'} {1e3 * v.clearance_m:.1f}" for v in done)
        print(f"episode {run}: {ep.result.outcome}; visits: {row}", flush=True)
    print(f"{args.scenario}: {visits} visits, reached {reached}, touching a fruit {touched}")


if __name__ == "__main__":
    main()
