"""The spheroid silhouette: exact residuals on a spheroid's grazing rays, and a fit that
finds a flattened fruit's centre where a circle through its equator cannot."""

import math

import numpy as np
import pytest

from bve_mj.perception.spheroid import fit_spheroid, grazing_residuals
from tests.conftest import finite_difference

F_PX = 462.0  # about the wrist camera's focal length


def _basis(u: np.ndarray) -> np.ndarray:
    e1 = np.cross(u, [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    return np.column_stack((e1, np.cross(u, e1), u))


def silhouette_rays(p: np.ndarray, a: float, k: float, up: np.ndarray, n: int = 360) -> np.ndarray:
    """Unit rays from the origin that graze the spheroid (centre p, equatorial radius a, polar
    k·a, axis up): x = p + L y with |y| = 1 and y·L⁻¹p = -1 (normal across the ray)."""
    B = _basis(up)
    L = B @ np.diag([a, a, k * a]) @ B.T
    q = np.linalg.solve(L, p)
    nq = float(np.linalg.norm(q))
    e = _basis(q / nq)
    t = np.linspace(0.0, 2.0 * math.pi, n, endpoint=False)
    y = -q / nq**2 + math.sqrt(1.0 - 1.0 / nq**2) * (
        np.outer(np.cos(t), e[:, 0]) + np.outer(np.sin(t), e[:, 1])
    )
    x = p + y @ L.T
    return x / np.linalg.norm(x, axis=1, keepdims=True)


UP = np.array([0.05, 0.0, 1.0]) / np.linalg.norm([0.05, 0.0, 1.0])  # a camera looking a little down


@pytest.mark.parametrize("k", [0.75, 1.0, 1.3])
def test_grazing_rays_have_zero_residual_and_inner_rays_are_positive(k):
    p = np.array([0.3, 0.02, -0.01]) / 0.03  # in equatorial radii
    rays = silhouette_rays(0.03 * p, 0.03, k, UP)
    assert np.max(np.abs(grazing_residuals(p, k, UP, rays))) < 1e-9
    centre = p / np.linalg.norm(p)
    inner = rays + 0.05 * (centre - rays)
    inner /= np.linalg.norm(inner, axis=1, keepdims=True)
    outer = rays - 0.05 * (centre - rays)
    outer /= np.linalg.norm(outer, axis=1, keepdims=True)
    assert np.all(grazing_residuals(p, k, UP, inner) > 0) and np.all(grazing_residuals(p, k, UP, outer) < 0)


def test_the_residual_is_the_angle_to_the_silhouette_for_a_sphere():
    p = np.array([10.0, 0.0, 0.0])  # sphere of radius 1 at 10: half-angle asin(0.1)
    alpha = math.asin(0.1)
    for off in (-0.004, 0.001, 0.004):  # up to ~2 px: first order (Sampson) is enough there
        ang = alpha - off
        ray = np.array([[math.cos(ang), math.sin(ang), 0.0]])
        assert grazing_residuals(p, 1.0, UP, ray)[0] == pytest.approx(off, rel=0.05)


def _cone_fit(rays: np.ndarray) -> tuple[np.ndarray, float]:
    w, *_ = np.linalg.lstsq(rays, np.ones(len(rays)), rcond=None)
    n = float(np.linalg.norm(w))
    return w / n, math.acos(1.0 / n)


@pytest.mark.parametrize("k", [0.8, 1.25])
def test_a_spheroid_fit_finds_the_centre_of_a_fruit_seen_in_part(k):
    """A flattened (or elongated) fruit with its top third hidden (a calyx, a leaf): the circle
    fit is pixels off, the spheroid fit a small fraction of a pixel."""
    a = 0.03
    centre = np.array([0.32, 0.03, 0.02])
    rays = silhouette_rays(centre, a, k, UP)
    rng = np.random.default_rng(3)
    rays = rays + rng.normal(0.0, 0.15 / F_PX, rays.shape)  # a sixth of a pixel of edge noise
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    top = rays @ UP
    seen = rays[top < np.quantile(top, 0.7)]
    truth = centre / np.linalg.norm(centre)
    axis0, alpha0 = _cone_fit(seen)
    circle_err_px = F_PX * float(np.linalg.norm(axis0 - truth))
    fit = fit_spheroid(seen, UP, axis0, alpha0, 1.0, 0.3, 1.0 / F_PX)
    assert fit is not None
    assert circle_err_px > 1.0
    assert F_PX * float(np.linalg.norm(fit.axis - truth)) < 0.1
    assert math.sin(fit.alpha) == pytest.approx(a / np.linalg.norm(centre), rel=2e-3)
    assert fit.shape_index == pytest.approx(k, rel=0.02)
    lat, sig_alpha = fit.sigmas((0.15 / F_PX) ** 2, 1.0, 0.3)
    assert 0.0 < lat < 0.2 / F_PX and 0.0 < sig_alpha < 0.2 / F_PX


def test_the_analytic_jacobian_matches_finite_differences_on_the_silhouette():
    """On the silhouette (g = 0) the Gauss-Newton Jacobian of the residual is its derivative."""
    from scipy.optimize import brentq

    from bve_mj.perception.spheroid import grazing_jacobian

    up = np.array([0.0, 0.1, 1.0]) / np.linalg.norm([0.0, 0.1, 1.0])
    p, k = np.array([8.0, 0.5, -0.3]), 0.85
    axis = p / np.linalg.norm(p)
    e1 = np.cross(axis, [0.0, 0.0, 1.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    rays = []
    for phi in np.linspace(0.0, 2.0 * np.pi, 24, endpoint=False):
        d = np.cos(phi) * e1 + np.sin(phi) * e2

        def g(t, d=d):
            b = axis + t * d
            return grazing_residuals(p, k, up, (b / np.linalg.norm(b))[None])[0]

        b = axis + brentq(g, 0.0, 0.5) * d
        rays.append(b / np.linalg.norm(b))
    rays = np.array(rays)
    x = np.append(p, np.log(k))

    def resid(xx):
        return grazing_residuals(xx[:3], np.exp(xx[3]), up, rays)

    fd = finite_difference(resid, x, 1e-7)
    np.testing.assert_allclose(grazing_jacobian(p, k, up, rays), fd, atol=1e-6 * np.abs(fd).max())
