"""Look-at IK: median time and success rate on reachable targets, per arm.

    python benchmarks/bench_ik.py [--targets 1000]

Targets are made reachable by construction: FK of a random configuration within the
limits, looking at a point 0.2-1.0 m along its optical axis. The IK starts from home.
Targets (issue 3): median at most 1 ms, success at least 99%.
"""

from __future__ import annotations

import time

import numpy as np

from bve_mj.cli.script import ScriptParser, guarded, integer
from bve_mj.robot import ROBOTS, ArmKinematics, get_robot, look_at_ik

LIMITS = {"manipulator_h": "emanual", "ur5": "urdf", "panda": "urdf"}


def main() -> None:
    ap = ScriptParser()
    ap.add_argument("--targets", type=integer(1), default=1000)
    args = ap.parse_args()
    print(f"look-at IK from home on {args.targets} reachable targets per arm (seed 0)")
    print(f"{'arm':<14} {'limits':<8} {'success %':>9} {'median ms':>9} {'p95 ms':>7} {'starts':>6}")
    for name in ROBOTS:
        kin = ArmKinematics(get_robot(name), LIMITS[name])
        rng = np.random.default_rng(0)
        times, ok, starts = [], 0, []
        for _ in range(args.targets):
            q = kin.random_configuration(rng)
            p, R = kin.camera_pose(q)
            target = p + R[:, 0] * rng.uniform(0.2, 1.0)
            t0 = time.perf_counter()
            res = look_at_ik(kin, p, target, kin.home, rng)
            times.append(time.perf_counter() - t0)
            ok += res.success
            starts.append(res.starts)
        t = np.array(times) * 1e3
        print(
            f"{name:<14} {LIMITS[name]:<8} {100 * ok / args.targets:9.1f} {np.median(t):9.3f} "
            f"{np.percentile(t, 95):7.2f} {np.mean(starts):6.2f}"
        )


if __name__ == "__main__":
    guarded(main)
