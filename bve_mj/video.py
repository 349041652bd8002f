"""Approach videos: an outside view with the camera's path, the true fruit and the estimate's
3σ ellipsoid, beside the eye-in-hand view with the detection drawn on it."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import cv2
import mujoco
import numpy as np

from bve_mj.episode import ViewRecord
from bve_mj.estimation.belief import Belief
from bve_mj.perception.detector import Detection, NoDetection
from bve_mj.sim.render import add_marker

__all__ = ["EpisodeRecorder", "draw_detection"]

_CYAN = (0, 255, 255)


def draw_detection(
    image_rgb: np.ndarray, det: Detection | NoDetection | None, caption: str = ""
) -> np.ndarray:
    """A copy of the image with the fitted silhouette and centre, or the reason for none."""
    img = np.ascontiguousarray(image_rgb).copy()
    if isinstance(det, Detection):
        c = tuple(int(x) for x in np.rint(det.centre_px).astype(int))
        cv2.circle(img, c, int(np.rint(det.radius_px)), _CYAN, 2, cv2.LINE_AA)
        cv2.drawMarker(img, c, _CYAN, cv2.MARKER_CROSS, 14, 2)
        text = f"range {det.range_m:.3f} m"
    elif isinstance(det, NoDetection):
        text = f"no detection: {det.reason}"
    else:
        text = ""
    for i, line in enumerate([caption, text]):
        if line:
            cv2.putText(
                img, line, (10, 26 + 26 * i), cv2.FONT_HERSHEY_SIMPLEX, 0.65, (255, 255, 255), 2, cv2.LINE_AA
            )
    return img


class EpisodeRecorder:
    """Collects frames while a MuJoCo episode runs and writes an mp4.

    Use ``on_step`` as the world's per-physics-step hook and ``on_view`` as the episode's
    per-view hook (``run_mujoco_episode(..., recorder=...)`` wires both).
    """

    def __init__(self, path: str | Path, fps: int = 25, hold_view_s: float = 0.4) -> None:
        self.path = Path(path)
        self.fps = fps
        self.hold_frames = max(1, round(hold_view_s * fps))
        self.frames_written = 0
        self._writer: Any = None
        self._world: Any = None
        self._belief: Belief | None = None
        self._path: list[np.ndarray] = []
        self._eye: np.ndarray | None = None
        self._next_t = 0.0
        self._view = 0

    # -- wiring
    def attach(self, world: Any, prior: Belief) -> None:
        import imageio.v2 as imageio

        self._world, self._belief = world, prior
        self._writer = imageio.get_writer(str(self.path), fps=self.fps, codec="libx264", macro_block_size=16)
        self._next_t = world.data.time

    def on_step(self, sim_time: float) -> None:
        if self._writer is not None and sim_time >= self._next_t:
            self._next_t = sim_time + 1.0 / self.fps
            self._write(self._compose())

    def on_view(self, record: ViewRecord) -> None:
        if self._writer is None:
            return
        self._belief = record.belief
        self._path.append(np.asarray(record.p_world_camera, dtype=float))
        self._view = record.iteration
        w = self._world
        if getattr(w.last, "image", None) is not None:
            err = 1e3 * float(np.linalg.norm(record.belief.mean - w.p_world_fruit))
            sig = 1e3 * float(np.sqrt(np.linalg.eigvalsh(record.belief.cov)[-1]))
            caption = f"view {record.iteration}: error {err:.1f} mm, sigma max {sig:.1f} mm"
            self._eye = draw_detection(w.last.image, w.last.detection, caption)
        frame = self._compose()
        for _ in range(self.hold_frames):
            self._write(frame)

    def close(self) -> int:
        """Finish the file; returns the number of frames written."""
        if self._writer is not None:
            self._writer.close()
            self._writer = None
        return self.frames_written

    # -- drawing
    def _decorate(self, scene: mujoco.MjvScene) -> None:
        eye3 = np.eye(3)
        for i, p in enumerate(self._path):
            add_marker(scene, mujoco.mjtGeom.mjGEOM_SPHERE, [0.008, 0, 0], p, eye3, [0.2, 0.55, 1.0, 1.0])
            if i > 0 and scene.ngeom < scene.maxgeom:
                g = scene.geoms[scene.ngeom]
                # mjv_connector sets only type, size, pos and mat: initialise the rest first,
                # or stale fields of an earlier frame's geom (a material id) reach the renderer
                mujoco.mjv_initGeom(
                    g, mujoco.mjtGeom.mjGEOM_CAPSULE, np.zeros(3), np.zeros(3), eye3.reshape(9),
                    np.array([0.2, 0.55, 1.0, 0.8], dtype=np.float32),
                )  # fmt: skip
                mujoco.mjv_connector(g, mujoco.mjtGeom.mjGEOM_CAPSULE, 0.003, self._path[i - 1], p)
                scene.ngeom += 1
        if self._belief is not None:
            w, V = np.linalg.eigh(self._belief.cov)
            size = np.maximum(3.0 * np.sqrt(np.maximum(w, 0.0)), 0.004)  # 3σ, drawn at least 4 mm
            add_marker(
                scene, mujoco.mjtGeom.mjGEOM_ELLIPSOID, size, self._belief.mean, V, [0.1, 0.9, 0.2, 0.45]
            )

    def _compose(self) -> np.ndarray:
        w = self._world
        truth = w.p_world_fruit
        lookat = 0.5 * (truth + np.array([0.1, 0.0, 0.3]))
        outside = w.renderer.render_free(w.data, lookat, 1.2, 35.0, -22.0, self._decorate)
        cv2.putText(outside, "blue: camera path   green: estimate (3 sigma)   red: true fruit", (10, 465),
                    cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)  # fmt: skip
        eye = self._eye if self._eye is not None else np.zeros_like(outside)
        return np.hstack([outside, eye])

    def _write(self, frame: np.ndarray) -> None:
        self._writer.append_data(frame)
        self.frames_written += 1
