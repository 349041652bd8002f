"""A simulated box detector: the true boxes of the fruit in view with a learned detector's
errors, to study their effect on localisation (``detector.kind = "synthetic_boxes"``).

Per image: each true box (from the scene's ground truth: the exact bounding box of the
fruit's projected ellipsoid, :func:`~bve_mj.perception.box_geometry.ellipsoid_box`) is missed
with probability ``miss_p``, else each of its four corner coordinates gets independent
Gaussian noise of σ ``noise_px``; then a Poisson(``false_positives``) number of false boxes,
fruit-sized (half-size ×0.5-1.5 the median true box's, or 8-60 px with no fruit in view,
aspect within ±10%), lie anywhere in the image. Boxes are clipped to the image, as a
detector's are (a fruit cut by the edge gets a box cut by it). Confidences: true boxes
U(0.5, 1), false ones U(0.25, 0.8); the boxes come most confident first.

It is a box source (``image -> (xyxy, confidence)``) for
:class:`~bve_mj.perception.adapters.BoxDetector`; the image is not looked at."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

__all__ = ["SyntheticBoxes"]


class SyntheticBoxes:
    """Noisy, incomplete and polluted true boxes.

    Args:
        truth: called once per image: the true boxes (n, 4) (u_min, v_min, u_max, v_max)
            [px] of the fruit in view, not clipped.
        image_size_px: (width, height) [px].
        rng: the stream of the noise, the misses and the false boxes.
        noise_px: σ of each corner coordinate [px].
        miss_p: probability that a fruit in view gets no box.
        false_positives: mean number of false boxes per image.
    """

    def __init__(
        self,
        truth: Callable[[], np.ndarray],
        image_size_px: tuple[int, int],
        rng: np.random.Generator,
        *,
        noise_px: float = 2.0,
        miss_p: float = 0.0,
        false_positives: float = 0.0,
    ) -> None:
        if not (noise_px >= 0.0 and 0.0 <= miss_p <= 1.0 and false_positives >= 0.0):
            raise ValueError(
                "noise_px >= 0, miss_p in [0, 1], false_positives >= 0; "
                f"got {noise_px}, {miss_p}, {false_positives}"
            )
        self.truth = truth
        self.width_px, self.height_px = (int(x) for x in image_size_px)
        self.rng = rng
        self.noise_px = float(noise_px)
        self.miss_p = float(miss_p)
        self.false_positives = float(false_positives)

    def __call__(self, image_rgb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(xyxy (n, 4) [px], confidence (n,)) for this view."""
        rng = self.rng
        true = np.asarray(self.truth(), dtype=float).reshape(-1, 4)
        kept = true[rng.random(len(true)) >= self.miss_p]
        noisy = kept + rng.normal(0.0, self.noise_px, kept.shape) if self.noise_px > 0 else kept.copy()
        conf_true = rng.uniform(0.5, 1.0, len(noisy))
        n_false = int(rng.poisson(self.false_positives)) if self.false_positives > 0 else 0
        if len(true):
            half = 0.25 * float(np.median(true[:, 2] - true[:, 0] + true[:, 3] - true[:, 1]))
            sizes = half * rng.uniform(0.5, 1.5, n_false)
        else:
            sizes = rng.uniform(8.0, 60.0, n_false)
        aspect = rng.uniform(0.9, 1.1, n_false)
        cu = rng.uniform(0.0, self.width_px, n_false)
        cv = rng.uniform(0.0, self.height_px, n_false)
        false = np.column_stack((cu - sizes * aspect, cv - sizes, cu + sizes * aspect, cv + sizes))
        conf_false = rng.uniform(0.25, 0.8, n_false)
        boxes = np.vstack((noisy, false.reshape(-1, 4)))
        conf = np.concatenate((conf_true, conf_false))
        boxes[:, [0, 2]] = np.clip(boxes[:, [0, 2]], 0.0, self.width_px)
        boxes[:, [1, 3]] = np.clip(boxes[:, [1, 3]], 0.0, self.height_px)
        real = (boxes[:, 2] > boxes[:, 0]) & (boxes[:, 3] > boxes[:, 1])
        boxes, conf = boxes[real], conf[real]
        order = np.argsort(-conf, kind="stable")
        return boxes[order], conf[order]
