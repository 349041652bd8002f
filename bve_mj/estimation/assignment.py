"""One view's detections and the fruit's tracks: a track from one detection, and the globally
optimal assignment of detections to tracks (see :mod:`bve_mj.estimation.tracks`).

A detection of a fruit is z = (t_y/t_x, t_z/t_x, α) of :class:`~bve_mj.estimation.models.
BearingSizeModel`: the bearing of its centre and its apparent angular radius."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from bve_mj.errors import EstimationError
from bve_mj.estimation.belief import Belief
from bve_mj.estimation.ekf import nis_threshold
from bve_mj.estimation.models import BearingSizeModel
from bve_mj.estimation.noise import Outline

__all__ = [
    "KNOWN_IMAGE_SHARE",
    "KNOWN_SIZE_REL",
    "Sighting",
    "assign",
    "belief_from_detection",
    "image_offset",
    "mismeasured",
]


KNOWN_IMAGE_SHARE = 0.5
"""A detection no track's gate admits, centred within this share of the apparent radius of a
known fruit (a confirmed track placed to within its radius) of that fruit's image centre,
its size within :data:`KNOWN_SIZE_REL` of the predicted, is that fruit mismeasured (a partly
hidden outline fitted off centre), not a new fruit (:func:`mismeasured`): it starts no track
(``cherry_truss`` 3326404843: three such detections of localised fruit started tracks wide
along their rays that took 8 of the episode's 16 views and were never seen again). A fruit
behind a known one, centred this near it, shows too little outline to be measured. A
tentative track is not known: two viewpoints may place it wrong, and a detection it does not
admit starts the track that replaces it (``ripe_truss`` 2442167650)."""

KNOWN_SIZE_REL = 0.25
"""|apparent size / predicted - 1| of a known fruit mismeasured: at most this."""


@dataclass(frozen=True)
class Sighting:
    """One fruit measured in one view: z = (t_y/t_x, t_z/t_x, α) and its model (the camera's
    pose at the view and the measurement's covariance); ``sensor_cov``: the part of that
    covariance the declared sensor errors make (encoder noise), None where none
    (:mod:`bve_mj.estimation.sensor_share`); ``outline``: what the detector saw of the fruit's
    outline (the claims' offset is conditioned on it), None where not known."""

    z: np.ndarray
    model: BearingSizeModel
    sensor_cov: np.ndarray | None = None
    outline: Outline | None = None


def detected_outline(det: Any) -> Outline | None:
    """What the built-in detector saw of a detection's outline (its neighbour share); None for
    one that states its own covariance (another detector's: the claims keep the noise model's
    bound over all fruits for it)."""
    return None if getattr(det, "measurement_cov", None) is not None else Outline(det.neighbour_share)


def belief_from_detection(
    sighting: Sighting,
    radius_m: float,
    radius_sigma_m: float,
    calibration_sigmas: tuple[float, float, float] | None = None,
) -> Belief:
    """The belief over (centre, radius) one detection gives with the radius prior
    N(``radius_m``, ``radius_sigma_m``²): the centre on the ray of its bearing, at the range
    ρ = r / sin α its apparent size gives with that radius; covariance by first-order
    propagation of the measurement's noise and the radius' spread (so range and radius are
    correlated, and the range is as uncertain as the radius is relatively).

    ``calibration_sigmas``: σ of the camera's calibration biases (δy, δz [rad], ε), when the
    state carries them (7,): they are appended at 0, and the centre's covariance takes their
    spread too, correlated with them (the detector measured ((u + δy)/(1 + ε), (v + δz)/(1 + ε),
    atan(tan α/(1 + ε))): :mod:`bve_mj.estimation.models`).

    Raises:
        EstimationError: if the measurement is not a fruit in front of the camera.
    """
    z = np.asarray(sighting.z, dtype=float)
    if z.shape != (3,) or not np.all(np.isfinite(z)) or not 0.0 < z[2] < 0.5 * math.pi:
        raise EstimationError(f"a track starts from a detection (u, v, alpha), got {z!r}")
    if not (radius_m > 0.0 and radius_sigma_m > 0.0):
        raise EstimationError(f"radius prior must be > 0, got {radius_m!r} +- {radius_sigma_m!r}")
    m = sighting.model
    u, v, alpha = z
    n = np.array([1.0, u, v])
    norm = float(np.linalg.norm(n))
    b = n / norm
    rho = radius_m / math.sin(alpha)
    R = m.R_world_camera
    centre = m.p_world_camera + rho * (R @ b)
    db_dn = (np.eye(3) - np.outer(b, b)) / norm
    J = np.zeros((4, 4))  # ∂(centre, r) / ∂(u, v, α, r)
    J[:3, 0] = rho * R @ db_dn[:, 1]
    J[:3, 1] = rho * R @ db_dn[:, 2]
    J[:3, 2] = R @ b * (-radius_m * math.cos(alpha) / math.sin(alpha) ** 2)
    J[:3, 3] = R @ b / math.sin(alpha)
    J[3, 3] = 1.0
    extra = () if calibration_sigmas is None else tuple(float(x) for x in calibration_sigmas)
    if extra and (len(extra) != 3 or not all(math.isfinite(x) and x > 0.0 for x in extra)):
        raise EstimationError(f"calibration sigmas must be 3 numbers > 0, got {calibration_sigmas!r}")
    dim = 4 + len(extra)
    if extra:
        # the true (u, v, α) at biases (δy, δz, ε) near 0: u = z_u (1 + ε) - δy, v likewise,
        # tan α = tan z_α (1 + ε): ∂u/∂δy = -1, ∂u/∂ε = z_u, ∂α/∂ε = sin α cos α
        J = np.pad(J, ((0, 3), (0, 3)))
        J[:3, 4] = -J[:3, 0]
        J[:3, 5] = -J[:3, 1]
        J[:3, 6] = u * J[:3, 0] + v * J[:3, 1] + math.sin(alpha) * math.cos(alpha) * J[:3, 2]
        J[4:, 4:] = np.eye(3)
    noise = np.zeros((dim, dim))
    noise[:3, :3] = np.asarray(m.noise_cov_z, dtype=float)
    noise[3, 3] = radius_sigma_m**2
    if extra:
        noise[4:, 4:] = np.diag(np.square(extra))
    cov = J @ noise @ J.T
    cov += np.eye(dim) * 1e-12  # the across-ray block is tiny but must stay definite
    return Belief(np.concatenate([centre, [radius_m], np.zeros(len(extra))]), cov)


def _innovation(belief: Belief, s: Sighting) -> tuple[float, float]:
    """(NIS, ln det S) of sighting ``s`` against ``belief``."""
    x = belief.mean
    y = np.asarray(s.z, dtype=float) - s.model.predict(x)
    H = s.model.jacobian(x)
    S = H @ belief.cov @ H.T + s.model.noise_cov
    S = 0.5 * (S + S.T)
    try:
        L = np.linalg.cholesky(S)
    except np.linalg.LinAlgError:
        return math.inf, 0.0
    w = np.linalg.solve(L, y)
    return float(w @ w), 2.0 * float(np.sum(np.log(np.diag(L))))


def _innovations(beliefs: Sequence[Belief], sightings: Sequence[Sighting]) -> tuple[np.ndarray, np.ndarray]:
    """The (n_beliefs, n_sightings) NIS and NIS + ln det S of every pair. The sightings of one
    view share the camera's pose, and h(x) and H(x) depend on the belief and the pose alone:
    each belief's prediction is made once per pose, the pairs' S factored in one batch (a
    pair whose S is not positive definite, or sightings of different kinds, pair by pair)."""
    if not beliefs or not sightings:
        return _pair_by_pair(beliefs, sightings)  # no pair: all inf
    models = [s.model for s in sightings]
    first = models[0]
    same = all(
        type(m) is type(first)
        and np.array_equal(m.p_world_camera, first.p_world_camera)
        and np.array_equal(m.R_world_camera, first.R_world_camera)
        for m in models
    )
    if not same:
        return _pair_by_pair(beliefs, sightings)
    h = np.array([np.atleast_1d(first.predict(b.mean)) for b in beliefs])  # (nb, m)
    HPH = np.array([(H := np.atleast_2d(first.jacobian(b.mean))) @ b.cov @ H.T for b in beliefs])
    z = np.array([np.asarray(s.z, dtype=float) for s in sightings])  # (ns, m)
    R = np.array([np.atleast_2d(m.noise_cov) for m in models])  # (ns, m, m)
    S = HPH[:, None] + R[None, :]
    S = 0.5 * (S + np.swapaxes(S, -1, -2))
    y = z[None, :, :] - h[:, None, :]
    try:
        L = np.linalg.cholesky(S)
    except np.linalg.LinAlgError:  # one pair's S not positive definite: each pair alone
        return _pair_by_pair(beliefs, sightings)
    w = np.linalg.solve(L, y[..., None])[..., 0]
    nis = np.sum(w * w, axis=-1)
    logdet = 2.0 * np.sum(np.log(np.diagonal(L, axis1=-2, axis2=-1)), axis=-1)
    return nis, nis + logdet


def _pair_by_pair(beliefs: Sequence[Belief], sightings: Sequence[Sighting]) -> tuple[np.ndarray, np.ndarray]:
    nis = np.full((len(beliefs), len(sightings)), math.inf)
    cost = np.full((len(beliefs), len(sightings)), math.inf)
    for i, b in enumerate(beliefs):
        for j, s in enumerate(sightings):
            d2, logdet = _innovation(b, s)
            nis[i, j], cost[i, j] = d2, d2 + logdet
    return nis, cost


def assign(
    beliefs: Sequence[Belief], sightings: Sequence[Sighting], gate_probability: float
) -> tuple[list[tuple[int, int]], np.ndarray]:
    """The globally optimal assignment of sightings to beliefs: (belief index, sighting index)
    pairs minimising the summed negative log-likelihood NIS + ln det S over the pairs whose NIS
    passes the gate (the χ²₃ quantile of ``gate_probability``); and the (n_beliefs,
    n_sightings) NIS matrix (inf where the innovation covariance is singular)."""
    nb, ns = len(beliefs), len(sightings)
    nis, cost = _innovations(beliefs, sightings)
    if nb == 0 or ns == 0:
        return [], nis
    gate = nis_threshold(gate_probability, 3)
    allowed = nis <= gate
    if not allowed.any():
        return [], nis
    from scipy.optimize import linear_sum_assignment

    finite = cost[allowed]
    big = float(np.max(finite) - np.min(finite)) * (nb + ns) + 1e6  # never worth taking
    rows, cols = linear_sum_assignment(np.where(allowed, cost, big))
    return [(int(i), int(j)) for i, j in zip(rows, cols, strict=True) if allowed[i, j]], nis


def image_offset(sighting: Sighting, belief: Belief) -> tuple[float, float] | None:
    """Where ``sighting`` lies against the image a fruit with ``belief`` (centre, radius)
    should have in its view: (the distance of its centre from that image's centre, in the
    fruit's apparent radii; its apparent angular radius over the fruit's). None where the fruit
    has no image from there (a radius not > 0, or the camera inside the fruit)."""
    m = sighting.model
    radius = belief.radius_m
    if radius is None or not 0.0 < radius < float(np.linalg.norm(belief.centre_m - m.p_world_camera)):
        return None
    u, v, alpha = m.predict(belief.mean)  # a fruit behind the camera lands far off
    offset = math.hypot(sighting.z[0] - u, sighting.z[1] - v) / math.tan(alpha)
    return offset, float(sighting.z[2]) / alpha


def mismeasured(sighting: Sighting, known: Sequence[Belief]) -> bool:
    """Whether ``sighting`` is one of the ``known`` fruit (each known to within its radius)
    mismeasured (:data:`KNOWN_IMAGE_SHARE`)."""
    for belief in known:
        offset = image_offset(sighting, belief)
        if offset is not None and offset[0] < KNOWN_IMAGE_SHARE and abs(offset[1] - 1.0) <= KNOWN_SIZE_REL:
            return True
    return False
