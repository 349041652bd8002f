"""The measurement a detection gives the filter, from the calibrated noise model."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from bve_mj.estimation.noise import NoiseModel

__all__ = ["measure"]


def measure(
    det: Any, noise: NoiseModel, shape_index: float, focal_px: float
) -> tuple[np.ndarray, np.ndarray]:
    """The measurement a :class:`~bve_mj.perception.detection.Detection` gives the bearing/size
    models: z = (a_y / a_x, a_z / a_x, α) with the apparent radius' bias removed, and its
    covariance (3, 3) [rad²] from the noise model.

    A detection that states its own covariance (``measurement_cov``: a box or mask from
    another detector, :mod:`bve_mj.perception.adapters`) keeps it, and its α as measured: the
    noise model and its bias are the built-in detector's."""
    a = det.bearing_camera
    own = getattr(det, "measurement_cov", None)
    if own is not None:
        z = np.array([a[1] / a[0], a[2] / a[0], det.angular_radius_rad])
        return z, np.array(own, dtype=float)
    sc, sr = noise.sigmas_px(
        det.radius_px, det.arc_deg, det.centre_fit_px, det.radius_fit_px, shape_index,
        getattr(det, "neighbour_share", 0.0),
    )  # fmt: skip
    sc = math.hypot(sc, getattr(det, "centre_disagreement_px", 0.0))  # the two fits' disagreement
    alpha = det.angular_radius_rad - noise.radius_bias(det.radius_px) / focal_px
    z = np.array([a[1] / a[0], a[2] / a[0], alpha])
    return z, np.diag([(sc / focal_px) ** 2, (sc / focal_px) ** 2, (sr / focal_px) ** 2])
