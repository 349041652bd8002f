"""One headless closed-loop episode, printed view by view (the same as `bve-mj episode`).

python examples/headless_episode.py [seed]
"""

from __future__ import annotations

import numpy as np

from bve_mj import Settings
from bve_mj.cli.script import SEED, ScriptParser, guarded
from bve_mj.loop.mujoco import run_mujoco_episode


def main(seed: int = 0) -> None:
    episode = run_mujoco_episode(Settings(), seed)  # the closed loop's defaults, as bve-mj episode
    for v in episode.result.views:
        err = 1e3 * np.linalg.norm(v.belief.centre_m - episode.truth)
        r, sd = v.belief.radius_m, v.belief.radius_sigma_m  # the fruit's radius is in the state
        size = f"radius {1e3 * r:5.2f} ± {1e3 * sd:4.2f} mm" if r is not None and sd is not None else ""
        print(f"view {v.iteration:2d}: detected={v.measured!s:5}  error {err:7.2f} mm  {size}")
    print(f"outcome {episode.result.outcome}, final error {episode.final_error_mm:.2f} mm, "
          f"true radius {1e3 * episode.true_radius_m:.2f} mm, {episode.result.wall_s:.2f} s")  # fmt: skip


if __name__ == "__main__":
    ap = ScriptParser(description=__doc__.splitlines()[0])
    ap.add_argument("seed", nargs="?", type=SEED, default=0)
    guarded(lambda: main(ap.parse_args().seed))
