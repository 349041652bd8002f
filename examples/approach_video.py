"""An approach episode (paper eq. 13: localise while moving in) recorded as an mp4, plus a
2x2 still of four moments of it (start, two midway, end) for the README. The arm keeps the
eye-in-hand image upright where it can (``planner.upright_weight``, 0.1 in MuJoCo by default).

    python examples/approach_video.py [OUT_DIR] [SEED]

Writes OUT_DIR/approach.mp4 and OUT_DIR/approach_frames.png (default OUT_DIR: out/, which git
ignores; the README's copies in assets/ were made from these).
"""

from __future__ import annotations

from pathlib import Path

import imageio.v2 as imageio
import numpy as np

from bve_mj import Settings
from bve_mj.cli.script import SEED, ScriptParser, folder, guarded
from bve_mj.config import with_overrides
from bve_mj.loop.mujoco import run_mujoco_episode
from bve_mj.reporting.video import EpisodeRecorder


def main(out_dir: str = "out", seed: int = 1) -> None:
    Path(out_dir).mkdir(parents=True, exist_ok=True)
    out = Path(out_dir) / "approach.mp4"
    settings = with_overrides(Settings(), episode={"approach": True, "views": 20})
    recorder = EpisodeRecorder(out)
    episode = run_mujoco_episode(settings, seed, recorder=recorder)
    frames = recorder.close()
    print(f"outcome {episode.result.outcome}, final error {episode.final_error_mm:.2f} mm")
    print(f"wrote {out} ({frames} frames)")
    reader = imageio.get_reader(out)
    all_frames = list(reader.iter_data())
    picks = [all_frames[int(i)][::2, ::2] for i in np.linspace(0, len(all_frames) - 1, 4)]
    still = np.vstack([np.hstack(picks[:2]), np.hstack(picks[2:])])
    png = out.with_name(out.stem + "_frames.png")
    imageio.imwrite(png, still)
    print(f"wrote {png}")


if __name__ == "__main__":
    ap = ScriptParser(description=__doc__.splitlines()[0])
    ap.add_argument("out_dir", nargs="?", type=folder, default="out")
    ap.add_argument("seed", nargs="?", type=SEED, default=1)
    args = ap.parse_args()
    guarded(lambda: main(args.out_dir, args.seed))
