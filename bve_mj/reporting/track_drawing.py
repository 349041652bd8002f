"""Tracks and marks drawn over images, for the every-fruit video
(:mod:`bve_mj.reporting.fruits_video`): each track's estimate and 3σ ellipsoid's outline over a
view of the scene, coloured by its state (tentative grey, confirmed yellow, localised magenta)
and tagged with its id, and circles with tags (detections, refused fruit, predicted discs)
over the eye-in-hand image. Tags are placed where they cover no other tag and stay in the
image, with a thin line to their point where they had to move away from it."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from bve_mj.loop.fruit_records import FruitState
from bve_mj.reporting.overlay import _BLACK, _EST, _FONT, _TRUTH, _WHITE, _i, _tag, _text_block, _View
from bve_mj.sim.scene_model import Fruit

__all__ = [
    "CONFIRMED",
    "LOCALISED",
    "TENTATIVE",
    "Box",
    "Colour",
    "Mark",
    "draw_marks",
    "draw_tracks",
    "state_colour",
]

Colour = tuple[int, int, int]

TENTATIVE: Colour = (190, 190, 190)
"""A tentative track (not yet confirmed): grey."""
CONFIRMED: Colour = (255, 210, 0)
"""A confirmed track not yet localised: yellow."""
LOCALISED: Colour = _EST
"""A localised track: magenta, as the one-target video's estimate."""
_LABEL_SCALE = 0.42
Box = tuple[int, int, int, int]


def state_colour(state: FruitState | None) -> Colour:
    """The colour of a track's state: tentative, confirmed or localised."""
    if state is None or not state.confirmed:
        return TENTATIVE
    return LOCALISED if state.localised else CONFIRMED


class _Labels:
    """Tags placed around points, each where it covers no tag placed before it, no reserved
    box and stays in the image (the first such of a few positions around the point, else the
    one overlapping least); a tag placed far from its point gets a thin line to it. Nothing
    is drawn until :meth:`draw`, which draws the lines under every tag."""

    _DIRS = (
        (1.0, 0.0), (-1.0, 0.0), (0.0, -1.0), (0.0, 1.0), (0.7, -0.7), (0.7, 0.7), (-0.7, -0.7), (-0.7, 0.7),
    )  # fmt: skip

    def __init__(self, width: int, height: int, reserved: Sequence[Box] = ()) -> None:
        self.width, self.height = width, height
        self.boxes: list[Box] = list(reserved)
        self._lines: list[tuple[tuple[int, int], tuple[int, int], Colour]] = []
        self._tags: list[tuple[str, tuple[int, int], float, Colour]] = []

    def reserve(self, box: Box) -> None:
        self.boxes.append(box)

    def _cost(self, box: Box) -> float:
        x0, y0, x1, y1 = box
        out = max(0, -x0) + max(0, x1 - self.width) + max(0, -y0) + max(0, y1 - self.height)
        cost = 1e3 * out
        for b in self.boxes:
            dx = min(x1, b[2]) - max(x0, b[0])
            dy = min(y1, b[3]) - max(y0, b[1])
            if dx > 0 and dy > 0:
                cost += dx * dy
        return cost

    def put_inside(self, text: str, centre: tuple[float, float], radius_px: float,
                   top: int, colour: Colour = _WHITE, scale: float = _LABEL_SCALE) -> Box | None:  # fmt: skip
        """Tag ``text`` inside a disc, below its centre (moved into the image where the centre
        is not), if it fits there without covering another tag; None where it does not."""
        (tw, th), base = cv2.getTextSize(text, _FONT, scale, 1)
        x = min(max(centre[0] - tw / 2, 4.0), self.width - tw - 4.0)
        y = min(max(centre[1] + 0.4 * radius_px, top + th + 6.0), self.height - base - 4.0)
        corners = (
            (x - 3, y - th - 3),
            (x + tw + 3, y - th - 3),
            (x - 3, y + base + 1),
            (x + tw + 3, y + base + 1),
        )
        if any(np.hypot(cx - centre[0], cy - centre[1]) > radius_px - 2.0 for cx, cy in corners):
            return None
        org = (_i(x), _i(y))
        box = (org[0] - 3, org[1] - th - 3, org[0] + tw + 3, org[1] + base + 1)
        if self._cost(box) > 0.0:
            return None
        self._tags.append((text, org, scale, colour))
        self.boxes.append(box)
        return box

    def put(self, text: str, centre: tuple[float, float], clear_px: float,
            colour: Colour = _WHITE, scale: float = _LABEL_SCALE) -> Box:  # fmt: skip
        """Tag ``text`` next to ``centre``, at least ``clear_px`` from it; returns its box."""
        (tw, th), base = cv2.getTextSize(text, _FONT, scale, 1)
        best: tuple[float, float, tuple[int, int], tuple[int, int], Box] | None = None
        for extra in (5.0, 18.0, 34.0, 55.0, 80.0):
            gap = clear_px + extra
            for dx, dy in self._DIRS:
                ax, ay = centre[0] + gap * dx, centre[1] + gap * dy
                x = ax if dx > 0.3 else ax - tw if dx < -0.3 else ax - tw / 2
                y = ay + th if dy > 0.3 else ay if dy < -0.3 else ay + th / 2
                org = (_i(x), _i(y))
                box = (org[0] - 3, org[1] - th - 3, org[0] + tw + 3, org[1] + base + 1)
                cost = self._cost(box)
                if best is None or cost < best[0]:
                    best = (cost, extra, org, (_i(ax), _i(ay)), box)
                if cost == 0.0:
                    break
            if best is not None and best[0] == 0.0:
                break
        assert best is not None
        _, extra, (x0, y0), anchor, box = best
        if extra > 20.0:  # far from its point: a line from the point's edge to the tag
            dx, dy = anchor[0] - centre[0], anchor[1] - centre[1]
            n = max(float(np.hypot(dx, dy)), 1e-9)
            edge = (_i(centre[0] + clear_px * dx / n), _i(centre[1] + clear_px * dy / n))
            self._lines.append((edge, anchor, colour))
        self._tags.append((text, (x0, y0), scale, colour))
        self.boxes.append(box)
        return box

    def draw(self, img: np.ndarray) -> None:
        """Draw the tags placed so far (their lines first), in place; forget them."""
        for a, b, colour in self._lines:
            cv2.line(img, a, b, _BLACK, 3, cv2.LINE_AA)
            cv2.line(img, a, b, colour, 1, cv2.LINE_AA)
        for text, org, scale, colour in self._tags:
            _tag(img, text, org, scale, colour)
        self._lines, self._tags = [], []


def draw_tracks(
    img: np.ndarray,
    cam: _View,
    tracks: Sequence[FruitState],
    ripe: Sequence[Fruit] = (),
    *,
    order: Mapping[int, int] | None = None,
    visiting: int | None = None,
    labels: _Labels | None = None,
) -> None:
    """Draw over a view of the scene (in place): the true ripe fruit's outlines; each
    track's estimate and 3σ ellipsoid's outline (where its long half-axis spans 3 px or
    more) in its state's colour, tagged ``#id`` (and ``pick k``, its place in the harvest
    ``order``, 1 first); the track being visited ringed in white."""
    h, w = img.shape[:2]
    labels = labels if labels is not None else _Labels(w, h)
    for f in ripe:
        (fuv,), (fz,) = cam.project(f.centre_m)
        if fz > 1e-3:
            c = (_i(fuv[0]), _i(fuv[1]))
            r_px = max(3, _i(cam.focal_px * f.radius_m / fz))
            cv2.circle(img, c, r_px, _BLACK, 3, cv2.LINE_AA)
            cv2.circle(img, c, r_px, _TRUTH, 1, cv2.LINE_AA)
    placed: list[tuple[FruitState, tuple[int, int], float]] = []
    for t in sorted(tracks, key=lambda t: (t.confirmed, t.localised)):  # localised drawn last, on top
        b = t.belief.position
        ell = cam.ellipse(b.mean, b.cov)
        if ell is None:
            continue
        (eu, ev), (a, bb, ang) = ell
        if not (np.isfinite(eu) and np.isfinite(ev)):
            continue
        c = (_i(eu), _i(ev))
        colour = state_colour(t)
        if a >= 3.0:
            axes = (min(_i(a), 4 * w), max(1, min(_i(bb), 4 * w)))
            cv2.ellipse(img, c, axes, ang, 0, 360, _BLACK, 4, cv2.LINE_AA)
            cv2.ellipse(img, c, axes, ang, 0, 360, colour, 2, cv2.LINE_AA)
        cv2.circle(img, c, 4, _BLACK, -1, cv2.LINE_AA)
        cv2.circle(img, c, 3, colour, -1, cv2.LINE_AA)
        z = float((b.mean - cam.pos) @ cam.forward)
        disc_px = cam.focal_px * float(t.belief.mean[3]) / z if t.belief.dim > 3 and z > 1e-3 else 6.0
        if t.id == visiting:
            ring = max(8, _i(disc_px) + 6)
            cv2.circle(img, c, ring, _BLACK, 5, cv2.LINE_AA)
            cv2.circle(img, c, ring, _WHITE, 2, cv2.LINE_AA)
        labels.reserve((c[0] - 4, c[1] - 4, c[0] + 4, c[1] + 4))
        placed.append((t, c, max(4.0, min(disc_px, 0.5 * a) if a >= 3.0 else 4.0)))
    for t, c, clear in sorted(placed, key=lambda p: p[0].id != visiting):  # the visited one first
        text = f"#{t.id}"
        if order is not None and t.id in order:
            text += f" pick {order[t.id] + 1}"
        labels.put(text, c, clear, _WHITE if t.id == visiting else state_colour(t))
    labels.draw(img)


@dataclass(frozen=True)
class Mark:
    """A circle drawn on the eye-in-hand image with its tag: a detection and what the
    tracker did with it, a refused fruit, or a track's predicted disc."""

    centre_px: tuple[float, float]
    radius_px: float
    label: str
    colour: Colour
    thickness: int = 2


def draw_marks(
    image_rgb: np.ndarray, marks: Sequence[Mark], lines: Sequence[tuple[str, Colour]]
) -> np.ndarray:
    """A copy of the image with each mark's circle and centre, its tag inside the circle (or
    beside it where it does not fit), and the caption ``lines`` on a band across the top."""
    img = np.ascontiguousarray(image_rgb).copy()
    h, w = img.shape[:2]
    top = 10 + 24 * len(lines) if lines else 0
    labels = _Labels(w, h, [(0, 0, w, top)])
    for m in marks:
        c = (_i(m.centre_px[0]), _i(m.centre_px[1]))
        r = max(2, _i(m.radius_px))
        cv2.circle(img, c, r, _BLACK, m.thickness + 2, cv2.LINE_AA)
        cv2.circle(img, c, r, m.colour, m.thickness, cv2.LINE_AA)
        cv2.drawMarker(img, c, m.colour, cv2.MARKER_CROSS, 10, max(1, m.thickness - 1))
        labels.reserve((c[0] - 6, c[1] - 6, c[0] + 6, c[1] + 6))
    for m in marks:  # inside its circle where it fits, else beside it
        if labels.put_inside(m.label, m.centre_px, m.radius_px, top, m.colour) is None:
            labels.put(m.label, m.centre_px, m.radius_px, m.colour)
    labels.draw(img)
    _text_block(img, lines)
    return img
