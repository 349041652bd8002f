"""One panel of a detector figure: an eye-in-hand image with the true silhouettes of the ripe
fruit, the fruit the every-fruit detector measured, and what it made of one fruit
(``examples/unhide_figure.py``, ``examples/pick_figure.py``)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np

from bve_mj.campaigns.calibration import fruit_images, matched_fruit
from bve_mj.perception.all_fruit import FruitDetections
from bve_mj.perception.detection import Intrinsics
from bve_mj.sim.scene_model import Fruit

__all__ = ["detector_panel", "side_by_side", "write_side_by_side"]

_WHITE, _GREEN, _MAGENTA = (255, 255, 255), (0, 255, 0), (255, 0, 255)  # BGR


def detector_panel(
    image_rgb: np.ndarray,
    fruits: Sequence[Fruit],
    shown: int,
    found: FruitDetections,
    p_world_camera: np.ndarray,
    R_world_camera: np.ndarray,
    intrinsics: Intrinsics,
    title: str,
) -> tuple[np.ndarray, str]:
    """The image (BGR) with each fruit of ``fruits`` outlined where it truly is (``shown``, an
    index into ``fruits``: white, the others green), every fruit ``found`` measured (magenta)
    and ``title``; and what the detector made of fruit ``shown``: "measured, N deg of
    outline", "refused: why", "not found" or "not in the image"."""
    images = fruit_images(list(fruits), p_world_camera, R_world_camera, intrinsics)
    panel = cv2.cvtColor(image_rgb, cv2.COLOR_RGB2BGR)
    for im in images:
        mine = im.fruit_index == shown
        c = (round(float(im.centre_px[0])), round(float(im.centre_px[1])))
        cv2.circle(panel, c, round(im.radius_px), _WHITE if mine else _GREEN, 2 if mine else 1)
    verdict = "not in the image" if all(im.fruit_index != shown for im in images) else "not found"
    for det in found.detections:
        c = (round(float(det.centre_px[0])), round(float(det.centre_px[1])))
        cv2.circle(panel, c, round(det.radius_px), _MAGENTA, 1)
        m = matched_fruit(det.centre_px, images)
        if m is not None and m.fruit_index == shown:
            verdict = f"measured, {det.arc_deg:.0f} deg of outline"
    if verdict == "not found":
        why = [
            r.reason
            for r in found.refused
            if r.centre_px is not None
            and (m := matched_fruit(r.centre_px, images)) is not None
            and m.fruit_index == shown
        ]
        verdict = f"refused: {why[0]}" if why else verdict
    cv2.putText(panel, title, (10, 30), cv2.FONT_HERSHEY_SIMPLEX, 0.9, _WHITE, 2)
    return panel, verdict


def side_by_side(panels: Sequence[np.ndarray], scale: float = 0.75) -> np.ndarray:
    """Panels of one height joined left to right with a white gap of 8 px, scaled by ``scale``."""
    gap = np.full((panels[0].shape[0], 8, 3), 255, np.uint8)
    row = [panels[0]]
    for panel in panels[1:]:
        row += [gap, panel]
    return cv2.resize(np.hstack(row), None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)


def write_side_by_side(panels: Sequence[np.ndarray], path: str | Path) -> Path:
    """:func:`side_by_side` of ``panels`` written to ``path`` (its folder made); the path."""
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(out), side_by_side(panels)):
        raise OSError(f"could not write {out}")
    return out
