"""Approach videos: an outside view that frames the fruit and the camera's path, beside the
eye-in-hand view with the detection drawn on it.

The outside view (:mod:`bve_mj.reporting.outside_view`) is a free camera placed, once per
episode, on the side from which the fruit and the start of the camera path are not hidden by
leaves, other fruit or the arm (checked with ray casts), and kept framing the region spanned
by the fruit and the camera path so far (it eases out as the path grows). What the legend
names is drawn on top of the rendered scene, so geometry never hides it: the camera path
(numbered at each view), the true fruit (its outline and centre) and the estimate with its 3σ
ellipsoid's outline. A zoom inset, centred on the true fruit, shows the estimate and its 3σ
ellipse at a scale where they can be seen once they are millimetres small. The eye-in-hand
overlay says which range is measured (from the detected silhouette and the assumed fruit
radius) and which is true."""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import numpy as np

from bve_mj.estimation.belief import Belief
from bve_mj.estimation.claim_shape import GAUSSIAN, ClaimShape
from bve_mj.loop.episode import ViewRecord
from bve_mj.reporting.outside_view import OutsideVideo
from bve_mj.reporting.overlay import (
    _BLACK,
    _EST,
    _FONT,
    _PATH,
    _TRUTH,
    _WHITE,
    _i,
    _mm,
    _shade,
    _tag,
    _View,
    draw_detection,
)
from bve_mj.sim.scene_model import fruit_geom_name

__all__ = ["EpisodeRecorder", "OutsideVideo"]

if TYPE_CHECKING:
    from bve_mj.sim.mujoco_world import MujocoWorld


class EpisodeRecorder(OutsideVideo):
    """Collects frames while a MuJoCo episode runs and writes an mp4.

    Use ``on_step`` as the world's per-physics-step hook and ``on_view`` as the episode's
    per-view hook (``run_mujoco_episode(..., recorder=...)`` wires both). Each frame is the
    outside view (left) beside the last eye-in-hand image (right), 1280 x 480 for the
    default 640 x 480 camera; one outside render per frame.
    """

    def __init__(self, path: str | Path, fps: int = 25, hold_view_s: float = 0.4) -> None:
        super().__init__(path, fps, hold_view_s)
        self._belief: Belief | None = None
        self._shape: ClaimShape = GAUSSIAN
        self._view = 0
        self._fruit = np.zeros(3)
        self._radius = 0.0

    # -- wiring
    def attach(self, world: MujocoWorld, prior: Belief, shape: ClaimShape = GAUSSIAN) -> None:
        self._open(world)
        self._shape = shape
        self._belief = prior.position
        self._fruit = np.asarray(world.p_world_fruit, dtype=float)
        self._radius = float(world.info.target.radius_m)
        self._azimuth, self._elevation = self._choose_side_of_fruit()

    def on_view(self, record: ViewRecord) -> None:
        if self._writer is None:
            return
        claim = self._shape.claim(
            record.belief, record.sensor_cov
        )  # what the view claims (its belief is the bound)
        self._belief = claim.position
        self._view = record.iteration
        here = self._mark_view()
        w = self.world
        if w.last.image is not None:
            err = _mm(float(np.linalg.norm(claim.centre_m - self._fruit)))
            sig = _mm(claim.sigma_max_m)
            caption = f"eye-in-hand, view {record.iteration}: error {err}, sigma max {sig}"
            prior = w.fruit_prior
            r, sd = claim.radius_m, claim.radius_sigma_m
            self._eye = draw_detection(
                w.last.image, w.last.detection, caption,
                assumed_radius_m=None if prior is None else float(prior.radius_m),
                true_range_m=float(np.linalg.norm(here - self._fruit)),
                true_radius_m=self._radius,
                radius_estimate_m=None if r is None or sd is None else (r, sd),
            )  # fmt: skip
        self._hold()

    # -- the outside camera
    def _choose_side_of_fruit(self) -> tuple[float, float]:
        """The side from which the fruit, the camera path's start and the way between are
        least hidden (:meth:`OutsideVideo._choose_side`); the arm's own camera housing may be
        hit near the path's start."""
        f, c0 = self._fruit, self._trail[0]
        target = self.world.model.geom(fruit_geom_name(self.world.info.target.name)).id
        pts = np.stack([f + self._radius * np.eye(3)[2], f - self._radius * np.eye(3)[2], f, c0])
        goals = ((f, 3.0, target, self._radius + 0.002), (0.5 * (f + c0), 1.0, -1, 0.0), (c0, 2.0, -1, 0.06))
        return self._choose_side(f, pts, goals)

    def _framing_points(self) -> list[np.ndarray]:
        pts = [self._fruit + s * self._radius * e for s in (-1.0, 1.0) for e in np.eye(3)]
        return pts + self._trail

    # -- drawing
    def _overlay(self, img: np.ndarray, cam: _View) -> None:
        h, w = img.shape[:2]
        self._draw_path(img, cam)
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

    def _inset(self, img: np.ndarray, cam: _View, size: int = 180) -> None:
        """A corner: the true fruit, the estimate and its 3σ ellipse, orthographic along the
        outside camera's axes, centred on the true fruit at a scale that shows the ellipse."""
        if self._belief is None:
            return
        h, w = img.shape[:2]
        x0, y0 = self._inset_corner(cam, w, h, size, self._fruit[None])
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
