"""Approach videos: an outside view that frames the fruit and the camera's path, beside the
eye-in-hand view with the detection drawn on it.

The outside view is a free camera placed, once per episode, on the side from which the fruit
and the start of the camera path are not hidden by leaves, other fruit or the arm (checked
with ray casts), and kept framing the region spanned by the fruit and the camera path so far
(it eases out as the path grows). What the legend names is drawn on top of the rendered
scene, so geometry never hides it: the camera path (numbered at each view), the true fruit
(its outline and centre) and the estimate with its 3σ ellipsoid's outline. A zoom inset,
centred on the true fruit, shows the estimate and its 3σ ellipse at a scale where they can be
seen once they are millimetres small. The eye-in-hand overlay says which range is measured
(from the detected silhouette and the assumed fruit radius) and which is true."""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

import cv2
import mujoco
import numpy as np

from bve_mj.estimation.belief import Belief
from bve_mj.loop.episode import ViewRecord
from bve_mj.reporting.overlay import (
    _BLACK,
    _EST,
    _FONT,
    _PATH,
    _TRUTH,
    _WHITE,
    _axes,
    _frame,
    _i,
    _mm,
    _shade,
    _tag,
    _text,
    _View,
    draw_detection,
)
from bve_mj.sim.arm import CAMERA_NAME
from bve_mj.sim.scene_model import fruit_geom_name

__all__ = ["EpisodeRecorder"]

if TYPE_CHECKING:
    from bve_mj.sim.mujoco_world import MujocoWorld


class EpisodeRecorder:
    """Collects frames while a MuJoCo episode runs and writes an mp4.

    Use ``on_step`` as the world's per-physics-step hook and ``on_view`` as the episode's
    per-view hook (``run_mujoco_episode(..., recorder=...)`` wires both). Each frame is the
    outside view (left) beside the last eye-in-hand image (right), 1280 x 480 for the
    default 640 x 480 camera; one outside render per frame.
    """

    def __init__(self, path: str | Path, fps: int = 25, hold_view_s: float = 0.4) -> None:
        self.path = Path(path)
        self.fps = fps
        self.hold_frames = max(1, round(hold_view_s * fps))
        self.frames_written = 0
        self._writer: Any = None
        self._world: MujocoWorld | None = None
        self._belief: Belief | None = None
        self._trail: list[np.ndarray] = []  # the true camera position at every frame
        self._views: list[np.ndarray] = []  # ... and at every view
        self._eye: np.ndarray | None = None
        self._next_t = 0.0
        self._view = 0
        self._cam_id = -1
        self._fruit = np.zeros(3)
        self._radius = 0.0
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

    # -- wiring
    def attach(self, world: MujocoWorld, prior: Belief) -> None:
        import imageio.v2 as imageio

        self._world, self._belief = world, prior.position
        self._writer = imageio.get_writer(str(self.path), fps=self.fps, codec="libx264", macro_block_size=16)
        self._next_t = world.data.time
        self._cam_id = int(world.model.camera(CAMERA_NAME).id)
        self._fruit = np.asarray(world.p_world_fruit, dtype=float)
        self._radius = float(world.info.target.radius_m)
        self._trail = [self._camera_now()]
        self._azimuth, self._elevation = self._choose_side()

    def on_step(self, sim_time: float) -> None:
        if self._writer is not None and sim_time >= self._next_t:
            self._next_t = sim_time + 1.0 / self.fps
            self._trail.append(self._camera_now())
            self._write(self._compose())

    def on_view(self, record: ViewRecord) -> None:
        if self._writer is None:
            return
        self._belief = record.belief.position
        self._view = record.iteration
        here = self._camera_now()
        self._trail.append(here)
        self._views.append(here)
        w = self.world
        if w.last.image is not None:
            err = _mm(float(np.linalg.norm(record.belief.centre_m - self._fruit)))
            sig = _mm(record.belief.sigma_max_m)
            caption = f"eye-in-hand, view {record.iteration}: error {err}, sigma max {sig}"
            prior = w.fruit_prior
            r, sd = record.belief.radius_m, record.belief.radius_sigma_m
            self._eye = draw_detection(
                w.last.image, w.last.detection, caption,
                assumed_radius_m=None if prior is None else float(prior.radius_m),
                true_range_m=float(np.linalg.norm(here - self._fruit)),
                true_radius_m=self._radius,
                radius_estimate_m=None if r is None or sd is None else (r, sd),
            )  # fmt: skip
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

    def _choose_side(self) -> tuple[float, float]:
        """(azimuth, elevation) [deg] of the outside camera: from the side of the line from
        the camera to the fruit (the arm reaches along it, so it does not hide the path), the
        candidate whose rays to the fruit and the camera path's start are least blocked."""
        m, d = self.world.model, self.world.data
        f, c0 = self._fruit, self._trail[0]
        a = (f - c0)[:2]
        if np.linalg.norm(a) < 1e-6:
            a = f[:2] if np.linalg.norm(f[:2]) > 1e-6 else np.array([1.0, 0.0])
        base = math.degrees(math.atan2(a[1], a[0]))
        target = m.geom(fruit_geom_name(self.world.info.target.name)).id
        w, h = self._size()
        pts = np.stack([f + self._radius * np.eye(3)[2], f - self._radius * np.eye(3)[2], f, c0])
        best: tuple[float, float, float] | None = None
        for tilt in (35.0, 60.0, 10.0):  # from the side, turned this far towards behind the camera
            for sign in (1.0, -1.0):
                for elevation in (-25.0, -40.0, -12.0):
                    azimuth = base + sign * (90.0 - tilt)
                    lookat, dist = _frame(pts, azimuth, elevation, self._fovy(), w / h)
                    fwd, _, _ = _axes(azimuth, elevation)
                    eye = lookat - dist * fwd
                    blocked = 0.0
                    for goal, weight, ok_geom, slack in (
                        (f, 3.0, target, self._radius + 0.002),
                        (0.5 * (f + c0), 1.0, -1, 0.0),
                        (c0, 2.0, -1, 0.06),  # the arm's own camera housing may be hit near c0
                    ):
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

    def _update_framing(self) -> None:
        w, h = self._size()
        pts = [self._fruit + s * self._radius * e for s in (-1.0, 1.0) for e in np.eye(3)]
        pts += self._trail
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
    def _overlay(self, img: np.ndarray, cam: _View) -> None:
        h, w = img.shape[:2]
        # camera path: the true camera position at every frame, a dot and number at each view
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
        # true fruit: outline at its true radius and its centre
        (fuv,), (fz,) = cam.project(self._fruit)
        if fz > 1e-3:
            c = (_i(fuv[0]), _i(fuv[1]))
            r_px = max(4, _i(cam.focal_px * self._radius / fz))
            cv2.circle(img, c, r_px, _BLACK, 4, cv2.LINE_AA)
            cv2.circle(img, c, r_px, _TRUTH, 2, cv2.LINE_AA)
            cv2.drawMarker(img, c, _TRUTH, cv2.MARKER_CROSS, 10, 2)
            _tag(img, "true fruit", (c[0] + r_px + 5, c[1] + r_px))
        # estimate and its 3σ ellipsoid's outline (too small to see here once converged: the inset)
        if self._belief is not None:
            ell = cam.ellipse(self._belief.mean, self._belief.cov)
            if ell is not None:
                (eu, ev), (a, b, ang) = ell
                c = (_i(eu), _i(ev))
                if a >= 3.0:
                    axes = (_i(a), max(1, _i(b)))
                    cv2.ellipse(img, c, axes, ang, 0, 360, _BLACK, 4, cv2.LINE_AA)
                    cv2.ellipse(img, c, axes, ang, 0, 360, _EST, 2, cv2.LINE_AA)
                cv2.circle(img, c, 5, _BLACK, -1, cv2.LINE_AA)
                cv2.circle(img, c, 3, _EST, -1, cv2.LINE_AA)
        self._inset(img, cam)
        # title and legend
        _shade(img, 0, 0, w, 30)
        cv2.putText(img, "outside view", (10, 21), _FONT, 0.55, _WHITE, 1, cv2.LINE_AA)
        _shade(img, 0, h - 30, w, h)
        y = h - 11
        cv2.line(img, (10, y - 4), (34, y - 4), _PATH, 2, cv2.LINE_AA)
        cv2.circle(img, (22, y - 4), 4, _PATH, -1, cv2.LINE_AA)
        cv2.putText(img, "camera path (n: view)", (40, y), _FONT, 0.45, _WHITE, 1, cv2.LINE_AA)
        cv2.circle(img, (226, y - 4), 7, _TRUTH, 2, cv2.LINE_AA)
        cv2.putText(img, "true fruit", (238, y), _FONT, 0.45, _WHITE, 1, cv2.LINE_AA)
        cv2.ellipse(img, (336, y - 4), (11, 6), 0, 0, 360, _EST, 2, cv2.LINE_AA)
        cv2.circle(img, (336, y - 4), 3, _EST, -1, cv2.LINE_AA)
        cv2.putText(img, "estimate, 3 sigma ellipsoid", (352, y), _FONT, 0.45, _WHITE, 1, cv2.LINE_AA)

    def _inset_corner(self, cam: _View, w: int, h: int, size: int) -> tuple[int, int]:
        """The top-left pixel of the zoom inset: the current corner unless the true fruit or
        the path's last stretch would lie under it, else the corner farthest from them."""
        (fuv,), _ = cam.project(self._fruit)
        uv, z = cam.project(np.array(self._trail[-40:]))
        keep = np.vstack([fuv[None], uv[z > 1e-3]])
        keep = keep[np.all(np.isfinite(keep), axis=1)]
        corners = [(w - size - 8, 38), (8, 38), (w - size - 8, h - size - 38), (8, h - size - 38)]

        def hits(c: tuple[int, int]) -> int:
            pad = 30
            inside = (
                (keep[:, 0] > c[0] - pad) & (keep[:, 0] < c[0] + size + pad)
                & (keep[:, 1] > c[1] - pad) & (keep[:, 1] < c[1] + size + pad)
            )  # fmt: skip
            return int(inside.sum()) + (1000 if len(keep) and inside[0] else 0)

        current = self._corner if self._corner in corners else corners[0]
        if hits(current) == 0:
            return current
        self._corner = min(corners, key=hits)
        return self._corner

    def _inset(self, img: np.ndarray, cam: _View, size: int = 180) -> None:
        """A corner: the true fruit, the estimate and its 3σ ellipse, orthographic along the
        outside camera's axes, centred on the true fruit at a scale that shows the ellipse."""
        if self._belief is None:
            return
        h, w = img.shape[:2]
        x0, y0 = self._inset_corner(cam, w, h, size)
        panel = (img[y0 : y0 + size, x0 : x0 + size] * 0.25).astype(np.uint8)
        axes2 = np.stack([cam.right, -cam.up])  # panel x right, y down
        err = axes2 @ (self._belief.mean - self._fruit)
        cov2 = axes2 @ self._belief.cov @ axes2.T
        wv, V = np.linalg.eigh(cov2)
        three = 3.0 * np.sqrt(np.maximum(wv, 0.0))
        extent = float(np.abs(err).max() + three.max())
        half = next((s for s in (0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5) if 0.8 * s >= extent), 1.0)
        scale = (size / 2) / half  # px per metre
        mid = size / 2

        def px(v: np.ndarray) -> tuple[int, int]:
            return _i(mid + scale * v[0]), _i(mid + scale * v[1])

        cv2.circle(panel, px(np.zeros(2)), _i(scale * self._radius), _TRUTH, 1, cv2.LINE_AA)
        cv2.drawMarker(panel, px(np.zeros(2)), _TRUTH, cv2.MARKER_CROSS, 16, 2)
        ang = math.degrees(math.atan2(V[1, 1], V[0, 1]))
        ax = (max(1, _i(scale * three[1])), max(1, _i(scale * three[0])))
        cv2.ellipse(panel, px(err), ax, ang, 0, 360, _EST, 2, cv2.LINE_AA)
        cv2.circle(panel, px(err), 3, _EST, -1, cv2.LINE_AA)
        bar = max(b for b in (0.0005, 0.001, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2) if b <= 0.55 * half)
        end = 10 + _i(scale * bar)
        cv2.line(panel, (10, size - 12), (end, size - 12), _WHITE, 2)
        cv2.putText(panel, f"{1e3 * bar:g} mm", (end + 5, size - 8), _FONT, 0.4, _WHITE, 1, cv2.LINE_AA)
        cv2.putText(panel, "zoom on the fruit", (6, 16), _FONT, 0.42, _WHITE, 1, cv2.LINE_AA)
        e = _mm(float(np.linalg.norm(self._belief.mean - self._fruit)))
        cv2.putText(panel, f"error {e}", (6, 34), _FONT, 0.42, _EST, 1, cv2.LINE_AA)
        cv2.rectangle(panel, (0, 0), (size - 1, size - 1), _WHITE, 1)
        img[y0 : y0 + size, x0 : x0 + size] = panel

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
