"""Which pixels are ripe fruit: the colour masks, and the image checks."""

from __future__ import annotations

import cv2
import numpy as np

from bve_mj.config import DetectorConfig

__all__ = ["red_mask", "ripe_mask"]

_OPEN_KERNEL = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5))


def ripe_mask(image_rgb: np.ndarray, cfg: DetectorConfig) -> np.ndarray:
    """Pixels of ripe hue (``cfg.ripe_hue_max``: red, or up to the ripeness class the
    settings accept; red wraps around hue 180), saturated and coloured enough (chroma, max -
    min of R, G, B, at least ``cfg.min_chroma``: in the shade of the canopy a red fruit is dark
    but still red, where noise gives a dark grey pixel any hue), and the skin of
    those fruit that a highlight or uneven colour turns orange (hue up to
    ``cfg.extend_hue_max``, in a region that touches ripe pixels): uint8 mask 0/255."""
    hsv = cv2.cvtColor(image_rgb, cv2.COLOR_RGB2HSV)
    low = (cfg.min_saturation, cfg.min_value)
    # chroma (max - min of R, G, B) is S·V/255: a hue is the camera's noise below it
    coloured = np.where(hsv[:, :, 1].astype(np.uint16) * hsv[:, :, 2] >= 255 * cfg.min_chroma, 255, 0).astype(
        np.uint8
    )
    wrap = cv2.bitwise_and(cv2.inRange(hsv, (cfg.red_hue_min_wrap, *low), (255, 255, 255)), coloured)
    ripe = cv2.bitwise_and(cv2.inRange(hsv, (0, *low), (cfg.ripe_hue_max, 255, 255)), coloured)
    ripe = cv2.bitwise_or(ripe, wrap)
    if cfg.extend_hue_max <= cfg.ripe_hue_max:
        return ripe
    skin = cv2.bitwise_and(cv2.inRange(hsv, (0, *low), (cfg.extend_hue_max, 255, 255)), coloured)
    skin = cv2.bitwise_or(skin, wrap)
    # only patches: the rim where red blends into green leaves is orange too, a pixel or
    # two wide; opening removes it (and any other sliver) before the patches join the red
    patch = cv2.morphologyEx(cv2.bitwise_and(skin, cv2.bitwise_not(ripe)), cv2.MORPH_OPEN, _OPEN_KERNEL)
    skin = cv2.bitwise_or(ripe, patch)
    n, labels = cv2.connectedComponents(skin, connectivity=8)
    touching = np.zeros(n, dtype=bool)
    touching[np.unique(labels[ripe > 0])] = True
    touching[0] = False
    return np.where(touching[labels], 255, 0).astype(np.uint8)


red_mask = ripe_mask

"""The former name of :func:`ripe_mask`."""


def _check_image(image: object) -> str | None:
    if not isinstance(image, np.ndarray):
        return f"image is a {type(image).__name__}, not a numpy array"
    if image.ndim != 3 or image.shape[2] != 3 or image.shape[0] < 8 or image.shape[1] < 8:
        return f"image shape {image.shape} is not (H >= 8, W >= 8, 3)"
    if image.dtype != np.uint8:
        return f"image dtype {image.dtype} is not uint8"
    return None
