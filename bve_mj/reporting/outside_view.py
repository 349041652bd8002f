"""The outside view the episode videos share: an mp4 writer, the true camera's path, and a
free camera that frames the scene from outside, beside the eye-in-hand panel.

The outside camera is placed, once per episode, on the side from which what the video is
about and the start of the camera path are not hidden by leaves, other fruit or the arm
(checked with ray casts), and kept framing what it is about and the camera path so far (it
eases out as the path grows). The pose and pinhole MuJoCo drew with are kept, so what is drawn
over the rendered scene (the camera path, numbered at each view, and what a subclass adds)
lands exactly where the geometry is and is never hidden by it."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import cv2
import mujoco
import numpy as np

from bve_mj.reporting.overlay import _BLACK, _PATH, _WHITE, _axes, _frame, _tag, _text, _View
from bve_mj.sim.arm import CAMERA_NAME

__all__ = ["OutsideVideo"]

if TYPE_CHECKING:
    from bve_mj.sim.mujoco_world import MujocoWorld


class OutsideVideo:
    """What the episode videos share: the mp4 writer, the true camera's path (at every frame
    and at every view), the outside camera (its side chosen once, its framing eased as the
    path grows, the pose and pinhole MuJoCo drew with kept to project the overlays exactly),
    and each frame composed as the outside view (left) beside the eye-in-hand panel (right).

    A subclass says what the outside view frames (:meth:`_framing_points`) and draws over it
    (:meth:`_overlay`), and sets ``_eye`` (the eye-in-hand panel) as views come.
    """

    def __init__(self, path: str | Path, fps: int = 25, hold_view_s: float = 0.4) -> None:
        self.path = Path(path)
        self.fps = fps
        self.hold_frames = max(1, round(hold_view_s * fps))
        self.frames_written = 0
        self._writer: Any = None
        self._world: MujocoWorld | None = None
        self._trail: list[np.ndarray] = []  # the true camera position at every frame
        self._views: list[np.ndarray] = []  # ... and at every view
        self._eye: np.ndarray | None = None
        self._next_t = 0.0
        self._cam_id = -1
        self._azimuth, self._elevation = 0.0, -25.0
        self._lookat: np.ndarray | None = None
        self._distance = 1.0
        self._glcam: _View | None = None
        self._corner: tuple[int, int] | None = None

    @property
    def world(self) -> MujocoWorld:
        """The world :meth:`attach` wired this recorder to."""
        if self._world is None:
            raise RuntimeError("the recorder is not attached to a world")
        return self._world

    def _open(self, world: MujocoWorld) -> None:
        """Wire to ``world``: open the writer, start the path at the camera's position."""
        import imageio.v2 as imageio

        self._world = world
        self._writer = imageio.get_writer(str(self.path), fps=self.fps, codec="libx264", macro_block_size=16)
        self._next_t = world.data.time
        self._cam_id = int(world.model.camera(CAMERA_NAME).id)
        self._trail = [self._camera_now()]

    def on_step(self, sim_time: float) -> None:
        if self._writer is not None and sim_time >= self._next_t:
            self._next_t = sim_time + 1.0 / self.fps
            self._trail.append(self._camera_now())
            self._write(self._compose())

    def _mark_view(self) -> np.ndarray:
        """The camera's position now, added to the path as a view."""
        here = self._camera_now()
        self._trail.append(here)
        self._views.append(here)
        return here

    def _hold(self) -> None:
        """The frame as it is now, held ``hold_view_s``."""
        frame = self._compose()
        for _ in range(self.hold_frames):
            self._write(frame)

    def close(self) -> int:
        """Finish the file; returns the number of frames written."""
        if self._writer is not None:
            self._writer.close()
            self._writer = None
        return self.frames_written

    # -- the outside camera
    def _camera_now(self) -> np.ndarray:
        return np.array(self.world.data.cam_xpos[self._cam_id], dtype=float)

    def _size(self) -> tuple[int, int]:
        r = self.world.renderer
        return int(r.width), int(r.height)

    def _fovy(self) -> float:
        return float(self.world.model.vis.global_.fovy)

    def _choose_side(
        self,
        centre: np.ndarray,
        framed: np.ndarray,
        goals: Sequence[tuple[np.ndarray, float, int, float]],
    ) -> tuple[float, float]:
        """(azimuth, elevation) [deg] of the outside camera: from the side of the line from
        the camera to ``centre`` (the arm reaches along it, so it does not hide the path),
        the candidate (framing the points ``framed``) whose rays to the ``goals`` are least
        blocked: each goal (point, weight, a geom the ray may hit (-1: none), slack [m]: a hit
        this close before the point does not count)."""
        m, d = self.world.model, self.world.data
        c0 = self._trail[0]
        a = (centre - c0)[:2]
        if np.linalg.norm(a) < 1e-6:
            a = centre[:2] if np.linalg.norm(centre[:2]) > 1e-6 else np.array([1.0, 0.0])
        base = math.degrees(math.atan2(a[1], a[0]))
        w, h = self._size()
        best: tuple[float, float, float] | None = None
        for tilt in (35.0, 60.0, 10.0):  # from the side, turned this far towards behind the camera
            for sign in (1.0, -1.0):
                for elevation in (-25.0, -40.0, -12.0):
                    azimuth = base + sign * (90.0 - tilt)
                    lookat, dist = _frame(framed, azimuth, elevation, self._fovy(), w / h)
                    fwd, _, _ = _axes(azimuth, elevation)
                    eye = lookat - dist * fwd
                    blocked = 0.0
                    for goal, weight, ok_geom, slack in goals:
                        vec = goal - eye
                        dist_goal = float(np.linalg.norm(vec))
                        geomid = np.zeros(1, dtype=np.int32)
                        hit = mujoco.mj_ray(m, d, eye, vec / dist_goal, None, 1, -1, geomid)
                        if hit >= 0 and hit < dist_goal - slack and int(geomid[0]) != ok_geom:
                            blocked += weight
                    if best is None or blocked < best[0]:
                        best = (blocked, azimuth, elevation)
                    if blocked == 0.0:
                        return azimuth, elevation
        assert best is not None
        return best[1], best[2]

    def _framing_points(self) -> list[np.ndarray]:
        """The points the outside view keeps in frame (the camera path by default)."""
        return list(self._trail)

    def _update_framing(self) -> None:
        w, h = self._size()
        pts = self._framing_points()
        lookat, dist = _frame(np.array(pts), self._azimuth, self._elevation, self._fovy(), w / h)
        if self._lookat is None:
            self._lookat, self._distance = lookat, dist
        else:  # ease towards the new framing (no jumps as the path grows)
            self._lookat = self._lookat + 0.2 * (lookat - self._lookat)
            self._distance += 0.2 * (dist - self._distance)

    def _grab_camera(self, scene: mujoco.MjvScene) -> None:
        """Keep the pose and pinhole MuJoCo draws with (to project the overlays exactly)."""
        g0, g1 = scene.camera[0], scene.camera[1]
        fwd = np.array(g0.forward, dtype=float)
        up = np.array(g0.up, dtype=float)
        w, h = self._size()
        focal = (h / 2) * float(g0.frustum_near) / float(g0.frustum_top)
        self._glcam = _View(
            0.5 * (np.array(g0.pos, dtype=float) + np.array(g1.pos, dtype=float)),
            np.cross(fwd, up), up, fwd, focal, ((w - 1) / 2, (h - 1) / 2),
        )  # fmt: skip

    # -- drawing
    def _draw_path(self, img: np.ndarray, cam: _View) -> None:
        """The camera path: the true camera position at every frame, a dot and number at each
        view, a ring where the camera is now."""
        uv, z = cam.project(np.array(self._trail))
        ok = z > 1e-3
        pts = np.rint(uv[ok]).astype(np.int32).reshape(-1, 1, 2)
        if len(pts) > 1:
            cv2.polylines(img, [pts], False, _BLACK, 5, cv2.LINE_AA)
            cv2.polylines(img, [pts], False, _PATH, 2, cv2.LINE_AA)
        if self._views:
            vuv, vz = cam.project(np.array(self._views))
            for i, (p, zz) in enumerate(zip(vuv, vz, strict=True)):
                if zz > 1e-3:
                    c = (int(p[0]), int(p[1]))
                    cv2.circle(img, c, 6, _BLACK, -1, cv2.LINE_AA)
                    cv2.circle(img, c, 4, _PATH, -1, cv2.LINE_AA)
                    _tag(img, str(i), (c[0] + 8, c[1] - 7))
        if ok[-1]:
            c = (int(uv[-1, 0]), int(uv[-1, 1]))
            cv2.circle(img, c, 9, _WHITE, 2, cv2.LINE_AA)  # where the camera is now

    def _inset_corner(self, cam: _View, w: int, h: int, size: int, keep_clear: np.ndarray) -> tuple[int, int]:
        """The top-left pixel of an inset: the current corner unless one of the points
        ``keep_clear`` (N, 3) or the path's last stretch would lie under it, else the corner
        with the fewest of them under it (a ``keep_clear`` point outweighing the path)."""
        fuv, _ = cam.project(keep_clear)
        uv, z = cam.project(np.array(self._trail[-40:]))
        keep = np.vstack([fuv, uv[z > 1e-3]])
        keep = keep[np.all(np.isfinite(keep), axis=1)]
        n_clear = int(np.all(np.isfinite(fuv), axis=1).sum())
        corners = [(w - size - 8, 38), (8, 38), (w - size - 8, h - size - 38), (8, h - size - 38)]

        def hits(c: tuple[int, int]) -> int:
            pad = 30
            inside = (
                (keep[:, 0] > c[0] - pad) & (keep[:, 0] < c[0] + size + pad)
                & (keep[:, 1] > c[1] - pad) & (keep[:, 1] < c[1] + size + pad)
            )  # fmt: skip
            return int(inside.sum()) + 1000 * int(inside[:n_clear].sum())

        current = self._corner if self._corner in corners else corners[0]
        if hits(current) == 0:
            return current
        self._corner = min(corners, key=hits)
        return self._corner

    def _overlay(self, img: np.ndarray, cam: _View) -> None:
        """What is drawn over the outside view (the camera path by default)."""
        self._draw_path(img, cam)

    def _compose(self) -> np.ndarray:
        w = self.world
        self._update_framing()
        assert self._lookat is not None
        outside = w.renderer.render_free(
            w.data, self._lookat, self._distance, self._azimuth, self._elevation, self._grab_camera
        )
        if self._glcam is not None:
            self._overlay(outside, self._glcam)
        if self._eye is not None:
            eye = self._eye
        else:
            eye = np.zeros_like(outside)
            _text(eye, "eye-in-hand: waiting for the first view", (10, 26), 0.55)
        return np.hstack([outside, eye])

    def _write(self, frame: np.ndarray) -> None:
        self._writer.append_data(frame)
        self.frames_written += 1
