"""Every-fruit videos (``bve-mj episode --fruits all --video out.mp4``): the outside view
beside the eye-in-hand view, as the one-target video (:mod:`bve_mj.reporting.video`; the
outside camera, camera path and frame layout are :mod:`bve_mj.reporting.outside_view`'s), with
every track drawn (:mod:`bve_mj.reporting.track_drawing`).

The outside view frames the true ripe fruit of the work zone, the tracks and the camera path
(numbered at each view). Over it: the true ripe fruit's outlines (red), every track's
estimate and 3σ ellipsoid's outline labelled with its id, coloured by its state (tentative
grey, confirmed yellow, localised magenta), and a strip of zoom panels, one per track,
centred on the true fruit the track lies on, at a scale where its 3σ ellipse can be seen
once it is millimetres small. In approach mode the harvest follows the search: each track's
place in the harvest order is written next to it and the fruit being visited is ringed.

The eye-in-hand view shows the image of the last view with every detection circled and
labelled with what the tracker did with it: the track it was assigned to (``#3``), the track
it started (``new #5``) or ``ignored``; the fruit the detector found but refused to measure
are circled thin and grey. During the harvest it shows the camera's image at each fruit
visited (rendered without the sensor's noise) with the localised tracks' discs drawn on it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import numpy as np

from bve_mj.loop.every_fruit import seen_in_part_id
from bve_mj.loop.fruit_records import FruitState, FruitsView
from bve_mj.planning.every_fruit import EXPLORE
from bve_mj.reporting.outside_view import OutsideVideo
from bve_mj.reporting.overlay import _FONT, _PATH, _TRUTH, _WHITE, _i, _mm, _shade, _View
from bve_mj.reporting.track_drawing import (
    CONFIRMED,
    LOCALISED,
    TENTATIVE,
    Box,
    Colour,
    Mark,
    _Labels,
    draw_marks,
    draw_tracks,
    state_colour,
)
from bve_mj.sim.arm import CAMERA_NAME
from bve_mj.sim.scene_model import Fruit, fruit_geom_name

if TYPE_CHECKING:
    from bve_mj.loop.harvest import Visit
    from bve_mj.sim.mujoco_world import MujocoWorld

__all__ = ["FruitsRecorder", "Mark", "draw_marks", "draw_tracks", "state_colour"]

_IGNORED: Colour = (150, 150, 150)


class FruitsRecorder(OutsideVideo):
    """Collects frames while an every-fruit episode runs and writes an mp4
    (``run_every_fruit_episode(settings, seed, recorder=...)`` wires it; the caller closes
    it). Each frame is the outside view (left) beside the eye-in-hand view (right), 1280 x 480
    for the default 640 x 480 camera; one outside render per frame, and one eye-in-hand
    render at each fruit the harvest visits."""

    def __init__(self, path: str | Path, fps: int = 25, hold_view_s: float = 0.4, zoom_px: int = 80) -> None:
        super().__init__(path, fps, hold_view_s)
        self.zoom_px = zoom_px
        self._ripe: list[Fruit] = []
        self._fruits: list[Fruit] = []
        self._zone = np.zeros(3)
        self._tracks: tuple[FruitState, ...] = ()
        self._view: FruitsView | None = None
        self._order: dict[int, int] | None = None
        self._visiting: int | None = None
        self._picked: set[int] = set()  # tracks whose fruit a visit took off the plant
        self._strip_top: bool | None = None

    # -- wiring
    def attach(self, world: MujocoWorld, ripe: Sequence[Fruit], zone_centre_m: np.ndarray) -> None:
        self._open(world)
        self._ripe = list(ripe)
        self._fruits = list(world.info.fruits)
        self._zone = np.asarray(zone_centre_m, dtype=float).copy()
        self._azimuth, self._elevation = self._choose_side_of_truss()

    def on_view(self, view: FruitsView) -> None:
        if self._writer is None:
            return
        self._order = self._visiting = None  # a survey's view: a harvest before it is over (picking)
        self._view, self._tracks = view, view.fruits
        self._mark_view()
        w = self.world
        if w.last.image is not None:
            self._eye = draw_marks(w.last.image, self._view_marks(view), self._view_caption(view))
        self._hold()

    def on_order(self, order: Sequence[int]) -> None:
        self._order = {tid: k for k, tid in enumerate(order)}

    def on_visit(self, track: int) -> None:
        self._visiting = track

    def on_visited(self, visit: Visit) -> None:
        if self._writer is None:
            return
        self._eye = self._visit_panel(visit)
        if visit.picked is not None:
            self._picked.add(visit.track)
        self._hold()

    # -- the outside camera
    def _choose_side_of_truss(self) -> tuple[float, float]:
        """The side from which the ripe fruit, the camera path's start and the way between
        are least hidden (:meth:`OutsideVideo._choose_side`)."""
        c0 = self._trail[0]
        m = self.world.model
        fruit = self._ripe
        centre = np.mean([f.centre_m for f in fruit], axis=0) if fruit else self._zone
        up = np.eye(3)[2]
        pts = [f.centre_m + s * f.radius_m * up for f in fruit for s in (1.0, -1.0)] + [centre, c0]
        goals = [
            (f.centre_m, 3.0 / len(fruit), m.geom(fruit_geom_name(f.name)).id, f.radius_m + 0.002)
            for f in fruit
        ]
        goals += [(0.5 * (centre + c0), 1.0, -1, 0.0), (c0, 2.0, -1, 0.06)]
        return self._choose_side(centre, np.array(pts), goals)

    def _framing_points(self) -> list[np.ndarray]:
        pts = [f.centre_m + s * f.radius_m * e for f in self._ripe for s in (-1.0, 1.0) for e in np.eye(3)]
        pts += [t.belief.centre_m for t in self._tracks]
        return pts + self._trail if pts else [self._zone, *self._trail]

    # -- drawing
    def _true_fruit_of(self, t: FruitState) -> Fruit | None:
        """The scene's fruit nearest the track's estimate, when within its radius."""
        if not self._fruits:
            return None
        d = [float(np.linalg.norm(t.belief.centre_m - f.centre_m)) for f in self._fruits]
        k = int(np.argmin(d))
        return self._fruits[k] if d[k] <= self._fruits[k].radius_m else None

    def _overlay(self, img: np.ndarray, cam: _View) -> None:
        h, w = img.shape[:2]
        self._draw_path(img, cam)
        strip = self._strip_box(cam, w, h)
        labels = _Labels(w, h, [(0, 0, w, 30), (0, h - 30, w, h), *([strip] if strip else [])])
        draw_tracks(
            img, cam, self._tracks, self._ripe, order=self._order, visiting=self._visiting, labels=labels
        )
        if strip:
            self._zoom_strip(img, cam, strip)
        # title and legend
        _shade(img, 0, 0, w, 30)
        cv2.putText(img, "outside view", (10, 21), _FONT, 0.55, _WHITE, 1, cv2.LINE_AA)
        status = self._status()
        (tw, _), _ = cv2.getTextSize(status, _FONT, 0.5, 1)
        cv2.putText(img, status, (w - tw - 10, 21), _FONT, 0.5, _WHITE, 1, cv2.LINE_AA)
        self._legend(img)

    def _status(self) -> str:
        tracks = self._tracks
        if self._order is not None:
            n = len(self._order)
            if self._visiting is None or self._visiting not in self._order:
                return f"harvest: {n} fruit to visit"
            return f"harvest: visiting #{self._visiting}, pick {self._order[self._visiting] + 1} of {n}"
        if self._view is None:
            return "start"
        loc = sum(t.localised for t in tracks)
        return f"view {self._view.iteration}: {len(tracks)} tracks, {loc} localised"

    def _legend(self, img: np.ndarray) -> None:
        h, w = img.shape[:2]
        _shade(img, 0, h - 30, w, h)
        y, x, s = h - 11, 10, 0.42

        def text(t: str, x: int) -> int:
            cv2.putText(img, t, (x, y), _FONT, s, _WHITE, 1, cv2.LINE_AA)
            return x + cv2.getTextSize(t, _FONT, s, 1)[0][0] + 14

        cv2.line(img, (x, y - 4), (x + 22, y - 4), _PATH, 2, cv2.LINE_AA)
        cv2.circle(img, (x + 11, y - 4), 4, _PATH, -1, cv2.LINE_AA)
        x = text("camera path (n: view)", x + 28)
        cv2.circle(img, (x + 7, y - 4), 7, _TRUTH, 2, cv2.LINE_AA)
        x = text("true ripe fruit", x + 19)
        x = text("#n: track, 3 sigma:", x)
        for name, colour in (("tentative", TENTATIVE), ("confirmed", CONFIRMED), ("localised", LOCALISED)):
            cv2.ellipse(img, (x + 9, y - 4), (9, 5), 0, 0, 360, colour, 2, cv2.LINE_AA)
            x = text(name, x + 22) - 4

    def _strip_box(self, cam: _View, w: int, h: int) -> Box | None:
        """Where the zoom strip goes: under the title or above the legend, whichever has fewer
        ripe fruit, tracks and recent path under it (kept unless the current one fills up)."""
        n = len(self._tracks)
        if n == 0:
            return None
        p = self.zoom_px
        per_row = max(1, (w - 16) // (p + 4))
        rows = min(2, -(-n // per_row))
        height = rows * (p + 4)
        pts = [f.centre_m for f in self._ripe] + [t.belief.centre_m for t in self._tracks]
        pts += self._trail[-40:] + self._views
        uv, z = cam.project(np.array(pts))
        uv = uv[(z > 1e-3) & np.all(np.isfinite(uv), axis=1)]

        def hits(top: bool) -> int:
            y0 = 34 if top else h - 34 - height
            return int(((uv[:, 1] > y0 - 10) & (uv[:, 1] < y0 + height + 10)).sum())

        if self._strip_top is None or hits(self._strip_top) > 0:
            self._strip_top = hits(True) <= hits(False)
        y0 = 34 if self._strip_top else h - 34 - height
        return (8, y0, w - 8, y0 + height)

    def _zoom_strip(self, img: np.ndarray, cam: _View, box: Box) -> None:
        """One panel per track (confirmed first, by id): orthographic along the outside
        camera's axes, centred on the true fruit the track lies on (on the estimate where it
        lies on none), at a scale that shows its 3σ ellipse; the panel's width in mm."""
        p = self.zoom_px
        per_row = max(1, (box[2] - box[0]) // (p + 4))
        rows = (box[3] - box[1]) // (p + 4)
        tracks = sorted(self._tracks, key=lambda t: (not t.confirmed, t.id))[: per_row * rows]
        axes2 = np.stack([cam.right, -cam.up])
        for k, t in enumerate(tracks):
            x0 = box[0] + (k % per_row) * (p + 4)
            y0 = box[1] + (k // per_row) * (p + 4)
            panel = (img[y0 : y0 + p, x0 : x0 + p] * 0.25).astype(np.uint8)
            b = t.belief.position
            truth = self._true_fruit_of(t)
            centre = truth.centre_m if truth is not None else b.mean
            err = axes2 @ (b.mean - centre)
            wv, V = np.linalg.eigh(axes2 @ b.cov @ axes2.T)
            three = 3.0 * np.sqrt(np.maximum(wv, 0.0))
            extent = float(np.abs(err).max() + three.max())
            steps = (0.001, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5)
            half = next((s for s in steps if 0.75 * s >= extent), 1.0)
            scale = (p / 2) / half
            mid = p / 2

            def px(v: np.ndarray, scale: float = scale, mid: float = mid) -> tuple[int, int]:
                return _i(mid + scale * v[0]), _i(mid + scale * v[1])

            colour = state_colour(t)
            if truth is not None:
                cv2.circle(panel, px(np.zeros(2)), _i(scale * truth.radius_m), _TRUTH, 1, cv2.LINE_AA)
                cv2.drawMarker(panel, px(np.zeros(2)), _TRUTH, cv2.MARKER_CROSS, 12, 1)
            ang = float(np.degrees(np.arctan2(V[1, 1], V[0, 1])))
            ax = (max(1, _i(scale * three[1])), max(1, _i(scale * three[0])))
            cv2.ellipse(panel, px(err), ax, ang, 0, 360, colour, 1, cv2.LINE_AA)
            cv2.circle(panel, px(err), 2, colour, -1, cv2.LINE_AA)
            cv2.putText(panel, f"#{t.id}", (4, 13), _FONT, 0.4, colour, 1, cv2.LINE_AA)
            width = f"{2e3 * half:g}mm"
            (tw, _), _ = cv2.getTextSize(width, _FONT, 0.33, 1)
            cv2.putText(panel, width, (p - tw - 3, 12), _FONT, 0.33, _WHITE, 1, cv2.LINE_AA)
            under = "no fruit" if truth is None else f"err {_mm(float(np.linalg.norm(b.mean - centre)))}"
            cv2.putText(panel, under, (4, p - 5), _FONT, 0.33, _WHITE, 1, cv2.LINE_AA)
            edge = _WHITE if t.id == self._visiting else (110, 110, 110)
            cv2.rectangle(panel, (0, 0), (p - 1, p - 1), edge, 1)
            img[y0 : y0 + p, x0 : x0 + p] = panel

    def _view_marks(self, view: FruitsView) -> list[Mark]:
        """Each detection of the view with what the tracker did with it, and the refused."""
        every = self.world.last.every
        if every is None:
            return []
        by_id = {t.id: t for t in view.fruits}
        assigned = dict(view.tracking.assigned)
        started = dict(view.tracking.started)
        marks = []
        for i, det in enumerate(every.detections):
            centre = (float(det.centre_px[0]), float(det.centre_px[1]))
            if i in assigned:
                tid = assigned[i]
                marks.append(Mark(centre, float(det.radius_px), f"#{tid}", state_colour(by_id.get(tid))))
            elif i in started:
                tid = started[i]
                marks.append(Mark(centre, float(det.radius_px), f"new #{tid}", state_colour(by_id.get(tid))))
            else:
                marks.append(Mark(centre, float(det.radius_px), "ignored", _IGNORED))
        for r in every.refused:
            if r.centre_px is not None and r.radius_px is not None:
                c = (float(r.centre_px[0]), float(r.centre_px[1]))
                marks.append(Mark(c, float(r.radius_px), "refused", _IGNORED, 1))
        return marks

    def _view_caption(self, view: FruitsView) -> list[tuple[str, Colour]]:
        loc = sum(t.localised for t in view.fruits)
        lines = [
            (
                f"eye-in-hand, view {view.iteration}: {view.detections} detected, "
                f"{len(view.fruits)} tracks, {loc} localised",
                _WHITE,
            )
        ]
        if view.planned_for is None:
            why = "the start pose" if view.iteration == 0 else "after the harvest: looking again"
        elif view.planned_for == EXPLORE:
            why = "planned to explore the work zone"
            if not math.isnan(view.zone_framed):
                why += f" ({100 * view.zone_framed:.0f}% framed so far)"
        elif view.planned_for < EXPLORE:
            why = f"planned for fruit #{seen_in_part_id(view.planned_for)} seen in part"
        else:
            why = f"planned for track #{view.planned_for}"
        every = self.world.last.every
        refused = 0 if every is None else len(every.refused)
        lines.append((why + (f"; {refused} more found but refused" if refused else ""), (0, 255, 255)))
        return lines

    def _visit_panel(self, visit: Visit) -> np.ndarray:
        """The camera's image at a visited fruit (no sensor noise), the localised tracks'
        discs drawn where their estimates project, the visited one in white (labelled
        ``picked`` when this visit took it; the fruit earlier visits took are not drawn)."""
        w = self.world
        image = w.renderer.render(w.data, CAMERA_NAME)
        from bve_mj.estimation.visibility import image_discs

        p, R = w.kin.camera_pose(w.q)
        tracks = [
            t for t in self._tracks
            if self._order is not None and t.id in self._order and t.id not in self._picked
        ]  # fmt: skip
        marks = []
        if tracks:
            cam = w.settings.camera
            centres = np.array([t.belief.centre_m for t in tracks])
            radii = np.array([float(t.belief.mean[3]) for t in tracks])
            uv, rad, front = image_discs(centres, radii, p, R, cam.focal_px, cam.width_px, cam.height_px)
            for t, c, r, ok in zip(tracks, uv, rad, front, strict=True):
                inside = -r < c[0] < cam.width_px + r and -r < c[1] < cam.height_px + r
                if ok and inside:
                    mine = t.id == visit.track
                    label = f"#{t.id}" + (" picked" if mine and visit.picked is not None else "")
                    marks.append(
                        Mark((float(c[0]), float(c[1])), float(r), label,
                             _WHITE if mine else state_colour(t), 2 if mine else 1)
                    )  # fmt: skip
        n = 0 if self._order is None else len(self._order)
        reached = "reached" if visit.reached else f"not reached: {visit.reason}"
        lines = [
            (f"eye-in-hand at pick {visit.order + 1} of {n}: track #{visit.track} ({reached})", _WHITE),
            (f"camera {_mm(visit.distance_m)} from its estimate (nearest true centre "
             f"{_mm(visit.true_distance_m)})", (0, 255, 255)),
            (f"least clearance of the arm to any fruit: {_clearance(visit.clearance_m)}", (0, 255, 255)),
        ]  # fmt: skip
        return draw_marks(image, marks, lines)


def _clearance(metres: float) -> str:
    if not np.isfinite(metres):
        return "-"
    if metres <= 0.0:
        return f"touched ({_mm(-metres)} deep)"
    return f">= {_mm(0.05)}" if metres >= 0.05 else _mm(metres)
