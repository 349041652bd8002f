"""What the detector takes and gives: the camera's intrinsics, the predicted projection of the
target, a detection (bearing, apparent size, covariance, what was seen) or the reason for none."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bve_mj.config import CameraConfig
from bve_mj.geometry import pixel_rays, project_point

__all__ = ["Detection", "Intrinsics", "NoDetection", "Prediction"]

_CHI2_3_999 = 16.266  # χ²(3) quantile at 0.999: a candidate the estimate allows


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics the detector assumes (square pixels) [px]."""

    focal_px: float
    width_px: int
    height_px: int
    cx_offset_px: float = 0.0
    cy_offset_px: float = 0.0

    @classmethod
    def from_camera(cls, camera: CameraConfig) -> Intrinsics:
        return cls(camera.focal_px, camera.width_px, camera.height_px)

    def rays(self, uv: np.ndarray) -> np.ndarray:
        offset = np.array([self.cx_offset_px, self.cy_offset_px])
        shifted = np.atleast_2d(np.asarray(uv, dtype=float)) - offset
        return pixel_rays(shifted, self.focal_px, self.width_px, self.height_px)

    def project(self, p_camera: np.ndarray) -> np.ndarray:
        uv = project_point(p_camera, self.focal_px, self.width_px, self.height_px)
        return uv + np.array([self.cx_offset_px, self.cy_offset_px])


@dataclass(frozen=True)
class Detection:
    """A measured tomato.

    Attributes:
        centre_px: image of the fitted cone axis (u, v) [px].
        radius_px: apparent radius f·tan α [px].
        bearing_camera: unit direction to the fruit centre in the camera frame, (3,).
        angular_radius_rad: α.
        range_m: ρ = r / sin α with the assumed radius.
        p_camera: fruit centre in the camera frame [m], (3,): the measurement z.
        cov_camera: its covariance [m²], (3, 3): range σ along the bearing, lateral σ across.
        area_px: blob area; boundary_points: silhouette points used in the fit;
        trimmed_fraction: share of boundary points rejected as occluder or image edges.
        arc_deg: how much of the fruit's outline the fit saw (10° sectors around its centre).
        centre_fit_px, radius_fit_px: the fit's own 1σ of the centre (across the bearing, the
            worse direction) and of the apparent radius, from its residuals and how much
            outline it saw [px, as f·angle].
        centre_jackknife_px, radius_jackknife_px: the spread of the fits that leave one arc
            of the outline out (0 for a single arc) [px, as f·angle].
        neighbour_share: the share of the fitted circle's rim where ripe colour goes on just
            outside it: a ripe neighbour touching or overlapping the fruit there (0 alone).
        centre_disagreement_px: how much farther the spheroid's centre lies from the circle
            fit's than the fruit's shape explains [px] (0 where they agree): the centre is that
            uncertain, and the filter adds it to the centre's σ.
        measurement_cov: the covariance (3, 3) [rad²] of z = (a_y/a_x, a_z/a_x, α) (bearing
            as normalised image coordinates, apparent angular radius) when the detector states
            its own noise (the box and mask adapters of :mod:`bve_mj.perception.adapters`);
            None: the calibrated noise model gives it (the built-in detector).
    The noise model (:mod:`bve_mj.estimation.noise`) turns these into the measurement's σ,
    unless ``measurement_cov`` says it.
    """

    centre_px: np.ndarray
    radius_px: float
    bearing_camera: np.ndarray
    angular_radius_rad: float
    range_m: float
    p_camera: np.ndarray
    cov_camera: np.ndarray
    area_px: int
    boundary_points: int
    trimmed_fraction: float
    arc_deg: float = 360.0
    centre_fit_px: float = 0.0
    radius_fit_px: float = 0.0
    centre_jackknife_px: float = 0.0
    radius_jackknife_px: float = 0.0
    neighbour_share: float = 0.0
    centre_disagreement_px: float = 0.0
    measurement_cov: np.ndarray | None = None


@dataclass(frozen=True)
class NoDetection:
    """Nothing measured, and why (``ambiguous``: more than one fruit fits the estimate).

    ``candidates``: when ambiguous, the rough 3-D centres of the fruit the estimate allowed,
    each (p_camera (3,), cov_camera (3, 3)) [m, m²] in the camera frame: the loop checks at
    the end whether the fruit it localised was told apart from them.

    ``partial``: a fruit was found but seen only in part (too little of its outline, or arcs
    that pin its centre down too loosely): something ripe is there that could not be
    measured, not a fragment, a speck or a merged blob."""

    reason: str
    candidates: tuple[tuple[np.ndarray, np.ndarray], ...] = ()
    partial: bool = False

    @property
    def ambiguous(self) -> bool:
        return self.reason.startswith("ambiguous")


@dataclass(frozen=True)
class Prediction:
    """Where the estimate puts the target, in the camera frame (x optical axis, y left, z up):
    N(p_camera, cov_camera) [m]. It picks the target among the fruit in view by Mahalanobis
    distance in 3-D (bearing and size-based range), not by pixel distance: a neighbour
    nearer in the image but at the wrong range, or outside the estimate's spread, loses."""

    p_camera: np.ndarray
    cov_camera: np.ndarray
