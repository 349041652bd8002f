"""Rims over a ripe neighbour: the edges inside the ripe mask that are a fruit's outline.

Where one red fruit lies over another the colour mask runs on over the junction: red on red
shows no outline. The nearer fruit's rim is still there in the image, as a step of
brightness: a sphere darkens towards its limb, and that dark rim meets the lit face of the
fruit behind. :func:`interior_edges` finds such edges (Canny on the brightness, away from the
mask's own boundary) and :func:`interior_arcs` makes them arcs of the blob they lie in, marked
``interior``: :func:`bve_mj.perception.instances.group_arcs` lets them join the fruit whose
circle they lie on and never seed one (a cast shadow, a blush or a highlight's rim is an edge
inside a fruit too). The fruit behind has no outline along the junction at all.

Pixel coordinates: chains in OpenCV's indices (x, y); arcs at pixel centres (+0.5), as the
detector's outlines are.
"""

from __future__ import annotations

import cv2
import numpy as np

from bve_mj.perception.instances import Arc, sharp_corners

__all__ = ["interior_arcs", "interior_edges"]


def interior_edges(image_rgb: np.ndarray, mask: np.ndarray, threshold: float) -> list[np.ndarray]:
    """The brightness edges inside the ripe mask, as chains of pixel indices (x, y) in order
    along each: where one red fruit's rim lies over another, the mask has no outline, but the
    rim's shading (a sphere darkens towards its limb) meets the other fruit's surface in a
    step of brightness. Canny on the HSV value channel (3×3 Sobel, L2 magnitude, hysteresis
    between ``threshold`` and half of it), kept more than three pixels inside the mask: the
    mask's own boundary is the outline, and the limb's shading just inside it is steep enough
    to make edges that run along it, a pixel or two in (they would pull a fit inwards). Each connected
    edge is one chain, its pixels in the order a walk along it first meets them."""
    inside = cv2.erode(mask, _INSIDE)
    x, y, w, h = cv2.boundingRect(inside)  # only where ripe pixels are: a few % of the image
    if w == 0 or h == 0:
        return []
    x0, y0 = max(x - 2, 0), max(y - 2, 0)  # the Sobel and the hysteresis look two pixels out
    x1, y1 = min(x + w + 2, mask.shape[1]), min(y + h + 2, mask.shape[0])
    r, g, b = cv2.split(image_rgb[y0:y1, x0:x1])
    value = cv2.max(cv2.max(r, g), b)  # HSV's V, without the conversion
    edges = cv2.Canny(value, 0.5 * threshold, threshold, L2gradient=True)
    edges[inside[y0:y1, x0:x1] == 0] = 0
    contours, _ = cv2.findContours(edges, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    chains = []
    for c in contours:
        pts = c[:, 0, :]
        # a one-pixel line's contour runs along it and back: keep each pixel's first visit
        _, first = np.unique(pts[:, 0].astype(np.int64) * 1_000_003 + pts[:, 1], return_index=True)
        chains.append(pts[np.sort(first)].astype(float) + (x0, y0))
    return chains


_INSIDE = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (7, 7))


def interior_arcs(chains: list[np.ndarray], outlines: list[np.ndarray], *, min_points: int = 8) -> list[Arc]:
    """Arcs from edge chains inside the ripe mask (:func:`interior_edges`),
    each cut at its sharp corners and numbered by the blob whose outline (of ``outlines``, (M,
    2) each, in the chains' pixels) holds it; chains in no blob, and pieces shorter than
    ``min_points``, are dropped. Points are shifted to pixel centres (+0.5), as the
    detector's outlines are."""
    boxes = [cv2.boundingRect(o.astype(np.float32)) for o in outlines]
    polys = [o.astype(np.float32) for o in outlines]
    arcs: list[Arc] = []
    for chain in chains:
        mid = (float(chain[len(chain) // 2, 0]), float(chain[len(chain) // 2, 1]))
        blob = next(
            (
                k
                for k, (x, y, w, h) in enumerate(boxes)
                if x <= mid[0] <= x + w
                and y <= mid[1] <= y + h
                and cv2.pointPolygonTest(polys[k], mid, False) >= 0
            ),
            None,
        )
        if blob is None:
            continue
        corners = sharp_corners(chain) if len(chain) >= 20 else np.zeros(0, dtype=int)
        corners = corners[(corners >= 5) & (corners < len(chain) - 5)]
        for piece in np.split(chain, corners):
            if len(piece) >= min_points:
                arcs.append(Arc(piece + 0.5, blob, True, interior=True))
    return arcs
