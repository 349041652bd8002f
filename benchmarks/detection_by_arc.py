"""How often the every-fruit detector measures a ripe fruit, by the outline the view shows of it.

    python benchmarks/detection_by_arc.py [--only truss_cluster,ripe_truss,cherry_truss]
        [--episodes 8] [--seed 7070]

Runs every-fruit episodes of the suite's scenarios and, for each view and each ripe fruit of
the work zone in front of the camera, the degrees of its outline that lie in the image and
outside every other fruit's image disc (the scene's truth, spheres:
:func:`~bve_mj.estimation.visibility.visible_arc_deg`), and whether the view measured it (a
track assigned or started in that view whose centre lies, seen from the camera, within half
the fruit's apparent radius of it). Prints the share measured per 30° of outline: the table
:data:`bve_mj.planning.zone_coverage.DETECTED_BY_ARC` was read from (seed 7070, 8 episodes
each of the three default scenarios).
"""

from __future__ import annotations

import math
import sys
from collections import defaultdict

import numpy as np

from bve_mj.campaigns.fruit_suite import episode_seed
from bve_mj.campaigns.scenarios import load_suite
from bve_mj.cli.script import SEED, ScriptParser, guarded, integer
from bve_mj.config import with_overrides
from bve_mj.estimation.visibility import visible_arc_deg
from bve_mj.loop.mujoco_fruits import run_every_fruit_episode

BIN_DEG = 30


def _bearing(point: np.ndarray, p: np.ndarray, R: np.ndarray) -> np.ndarray | None:
    t = (point - p) @ R
    return None if t[0] <= 0.0 else t[1:] / t[0]


def main() -> None:
    ap = ScriptParser(description=__doc__)
    ap.add_argument("--only", default="truss_cluster,ripe_truss,cherry_truss", help="scenario names")
    ap.add_argument("--episodes", type=integer(1, 200), default=8, help="episodes per scenario")
    ap.add_argument("--seed", type=SEED, default=7070, help="base seed")
    args = ap.parse_args()
    names = [n.strip() for n in args.only.split(",") if n.strip()]
    known = {sc.name for sc in load_suite()}
    bad = [n for n in names if n not in known]
    if not names or bad:
        allowed = ", ".join(sorted(known))
        ap.error(f"--only: got {args.only!r}; allowed: scenario names of the suite ({allowed})")
    counts: dict[int, list[int]] = defaultdict(lambda: [0, 0])
    for name in names:
        sc = load_suite(only=[name])[0]
        s = with_overrides(sc.settings(), tracking={"fruits": "all"})
        cam = s.camera
        for run in range(args.episodes):
            ep = run_every_fruit_episode(s, episode_seed(args.seed, run))
            fruit = list(ep.info.fruits)
            C = np.array([x.centre_m for x in fruit])
            radii = np.array([x.radius_m for x in fruit])
            for v in ep.result.views:
                if v.world is None or "camera_rotation" not in v.world:
                    continue
                p, R = np.asarray(v.p_world_camera), np.asarray(v.world["camera_rotation"])
                arcs = visible_arc_deg(C, radii, p, R, cam.focal_px, cam.width_px, cam.height_px)
                measured = {tid for _, tid in (*v.tracking.assigned, *v.tracking.started)}
                centres = [t.belief.centre_m for t in v.fruits if t.id in measured]
                for x in ep.ripe:
                    b = _bearing(x.centre_m, p, R)
                    if b is None:
                        continue
                    rho = float(np.linalg.norm(x.centre_m - p))
                    half = 0.5 * math.tan(math.asin(min(x.radius_m / rho, 1.0)))
                    seen = any(
                        (c := _bearing(t, p, R)) is not None and float(np.linalg.norm(c - b)) < half
                        for t in centres
                    )
                    k = int(arcs[fruit.index(x)] // BIN_DEG) * BIN_DEG
                    counts[k][0] += int(seen)
                    counts[k][1] += 1
            print(f"{name} {run + 1}/{args.episodes}", file=sys.stderr, flush=True, end="\r")
    print(file=sys.stderr)
    print(f"every-fruit detector, {len(names)} scenarios x {args.episodes} episodes (seed {args.seed})")
    total = sum(t for _, t in counts.values())
    for k in sorted(counts):
        d, t = counts[k]
        print(f"outline {k:3d}-{k + BIN_DEG - 1:3d} deg: measured {d:4d} of {t:4d} views ({d / t:.2f})")
    print(f"{total} views of a ripe fruit in front of the camera")


if __name__ == "__main__":
    guarded(main)
