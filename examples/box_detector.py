"""Bring your own detector: plug a bounding-box detector into the closed loop.

python examples/box_detector.py [seed] [scenario]

The loop needs one function from you: image -> (xyxy, confidence), boxes (n, 4) as
(u_min, v_min, u_max, v_max) in pixels and their confidences (n,), as ultralytics and
supervision give them. Here a colour threshold stands in for the network (replace
``my_boxes`` with yours); the box adapter turns each box into the measurement the filter
fuses (the bearing of the fruit's centre and its apparent size, with the covariance of the
box corners' noise), picks the box the estimate means, and refuses boxes cut by the image
edge. A YOLO model would be, for instance::

    from ultralytics import YOLO
    model = YOLO("tomato.pt")

    def my_boxes(image_rgb):
        r = model(image_rgb[..., ::-1], verbose=False)[0]  # ultralytics takes BGR arrays
        return r.boxes.xyxy.cpu().numpy(), r.boxes.conf.cpu().numpy()

Runs the `clean` scenario's episode (``bve-mj episode --config
examples/scenarios/suite/clean.toml --seed S`` with your boxes instead of the built-in
detector) and prints it view by view: the boxes measured, and why the adapter refused the
others (a box the fruit's stem or a leaf cuts is not the shape of a fruit's image).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from bve_mj.cli.script import SEED, ScriptParser, guarded
from bve_mj.config import load_settings
from bve_mj.loop.mujoco import run_mujoco_episode
from bve_mj.perception import BoxDetector


def my_boxes(image_rgb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Your detector: boxes of the red blobs (confidence: how much of its box a blob fills)."""
    hsv = cv2.cvtColor(image_rgb, cv2.COLOR_RGB2HSV)
    low = cv2.inRange(hsv, (0, 110, 40), (8, 255, 255))  # red wraps around hue 0
    high = cv2.inRange(hsv, (170, 110, 40), (180, 255, 255))
    red = cv2.bitwise_or(low, high)
    n, _, stats, _ = cv2.connectedComponentsWithStats(red)
    boxes, conf = [], []
    for x, y, w, h, area in stats[1:n]:
        if area >= 50:
            boxes.append((x, y, x + w, y + h))
            conf.append(area / (w * h) / (np.pi / 4))  # a disc fills pi/4 of its box
    return np.array(boxes, dtype=float).reshape(-1, 4), np.clip(np.array(conf), 0.0, 1.0)


def main(seed: int = 0, scenario: str = "clean") -> None:
    here = Path(__file__).resolve().parent
    settings = load_settings(here / "scenarios" / "suite" / f"{scenario}.toml")
    # corner noise of your detector [px]: measure it on labelled images
    detector = BoxDetector.from_settings(my_boxes, settings, corner_sigma_px=1.5)
    episode = run_mujoco_episode(settings, seed, detector=detector)
    for v in episode.result.views:
        err = 1e3 * np.linalg.norm(v.belief.centre_m - episode.truth)
        det = (v.world or {}).get("detection", {})
        seen = f"r {det['radius_px']:5.1f} px" if isinstance(det, dict) and "radius_px" in det else "refused"
        print(f"view {v.iteration:2d}: {seen:<11} error {err:7.2f} mm")
        if isinstance(det, dict) and "none" in det:
            print(f"         ({det['none']})")
    print(
        f"{scenario}, seed {seed}: {episode.result.outcome}, final error {episode.final_error_mm:.2f} mm, "
        f"{episode.result.wall_s:.2f} s"
    )


if __name__ == "__main__":
    ap = ScriptParser(description=__doc__.splitlines()[0])
    ap.add_argument("seed", nargs="?", type=SEED, default=0)
    ap.add_argument("scenario", nargs="?", default="clean", help="a scenario of the suite")
    args = ap.parse_args()
    guarded(lambda: main(args.seed, args.scenario))
