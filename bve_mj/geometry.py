"""Camera geometry: the paper's camera frame R_C^W (eqs. 4-8), look-at poses, projection.

Frames: the camera frame C has x along the viewing direction (the paper's convention,
and the tool x axis of the arm's flange), y horizontal (parallel to the world xy plane),
z = x × y. ``R_world_camera`` has the camera axes as columns, so
``p_world = R_world_camera @ p_camera + p_world_camera``.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "VERTICAL_EPS",
    "camera_frame",
    "camera_rotation",
    "camera_rotation_derivative",
    "frame_rotation",
    "frame_rotation_derivative",
    "look_at_pose",
    "pixel_rays",
    "project_point",
    "project_points",
    "ray_frame",
    "skew",
    "unit",
]

VERTICAL_EPS = 1e-9
"""Below this horizontal norm of the viewing direction, y_C falls back to the world y axis."""


def skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrix [v]× such that [v]× w = v × w."""
    a, b, c = v.tolist() if isinstance(v, np.ndarray) else v
    return np.array([[0.0, -c, b], [c, 0.0, -a], [-b, a, 0.0]])


_A = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])  # x -> (-x2, x1, 0)

_Frame = tuple[float, float, float, float, float, float, float, float, float, float, float]


def _frame(p_world_camera: np.ndarray, p_world_target: np.ndarray) -> _Frame:
    """x_C, y_C, z_C (as 9 floats), ‖k - c‖ and the horizontal norm m of x_C (0 at the
    vertical fallback). The hot path of the planner's objective: the components are handled
    as floats (each operation rounded as NumPy rounds it on arrays: the same bits)."""
    u = np.asarray(p_world_target, dtype=float) - np.asarray(p_world_camera, dtype=float)
    n = math.sqrt(float(u @ u))
    if n == 0.0:
        raise ValueError("camera and target coincide: the viewing direction is undefined")
    x0, x1, x2 = (u / n).tolist()
    m = math.hypot(x0, x1)
    if m > VERTICAL_EPS:
        y0, y1 = -x1 / m, x0 / m
    else:  # straight up or down: any horizontal axis will do; take world y
        y0, y1 = 0.0, 1.0
        m = 0.0
    y2 = 0.0
    z0, z1, z2 = x1 * y2 - x2 * y1, x2 * y0 - x0 * y2, x0 * y1 - x1 * y0  # x × y
    return x0, x1, x2, y0, y1, y2, z0, z1, z2, n, m


def camera_rotation(p_world_camera: np.ndarray, p_world_target: np.ndarray) -> np.ndarray:
    """R_C^W of a camera at ``p_world_camera`` looking at ``p_world_target`` (paper eqs. 4-8).

    Columns: x_C = unit viewing direction; y_C = normalize(-x2, x1, 0) (horizontal);
    z_C = x_C × y_C. Looking straight up or down, y_C is the world y axis. (3, 3).

    Raises:
        ValueError: if the camera and the target coincide.
    """
    return frame_rotation(_frame(p_world_camera, p_world_target))


def camera_rotation_derivative(
    p_world_camera: np.ndarray, p_world_target: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """R_C^W and ∂R_C^W/∂c: (3, 3) and (3, 3, 3) whose ``[:, :, j]`` is ∂R/∂c_j.

    Analytic: dx/dc = -(I - x xᵀ)/‖k - c‖; dy/dx = (I - y yᵀ) A / ‖A x‖ with A x =
    (-x2, x1, 0); dz = dx × y + x × dy. At the vertical fallback y is constant.
    """
    frame = _frame(p_world_camera, p_world_target)
    return frame_rotation(frame), frame_rotation_derivative(frame)


def camera_frame(p_world_camera: np.ndarray, p_world_target: np.ndarray) -> _Frame:
    """The camera frame of :func:`camera_rotation` as floats, for :func:`frame_rotation` and
    :func:`frame_rotation_derivative` (the planner takes the derivative only when asked)."""
    return _frame(p_world_camera, p_world_target)


def frame_rotation(frame: _Frame) -> np.ndarray:
    """R_C^W of a :func:`camera_frame`."""
    x0, x1, x2, y0, y1, y2, z0, z1, z2, _, _ = frame
    return np.array([[x0, y0, z0], [x1, y1, z1], [x2, y2, z2]])


def frame_rotation_derivative(frame: _Frame) -> np.ndarray:
    """∂R_C^W/∂c of a :func:`camera_frame` (see :func:`camera_rotation_derivative`)."""
    x0, x1, x2, y0, y1, y2, _, _, _, n, m = frame
    # (x xᵀ - I)/n and I - y yᵀ entry by entry: the same operations as on the arrays
    dx = np.array(
        [
            [(x0 * x0 - 1.0) / n, (x0 * x1 - 0.0) / n, (x0 * x2 - 0.0) / n],
            [(x1 * x0 - 0.0) / n, (x1 * x1 - 1.0) / n, (x1 * x2 - 0.0) / n],
            [(x2 * x0 - 0.0) / n, (x2 * x1 - 0.0) / n, (x2 * x2 - 1.0) / n],
        ]
    )  # column j = dx/dc_j
    dR = np.empty((3, 3, 3))  # dR[row i, column (x|y|z), j]
    dR[:, 0, :] = dx
    if m > 0.0:
        P = np.array(
            [
                [1.0 - y0 * y0, 0.0 - y0 * y1, 0.0 - y0 * y2],
                [0.0 - y1 * y0, 1.0 - y1 * y1, 0.0 - y1 * y2],
                [0.0 - y2 * y0, 0.0 - y2 * y1, 1.0 - y2 * y2],
            ]
        )
        dy = (P @ _A / m) @ dx
    else:
        dy = np.zeros((3, 3))
    dR[:, 1, :] = dy
    sx = np.array([[0.0, -x2, x1], [x2, 0.0, -x0], [-x1, x0, 0.0]])
    sy = np.array([[0.0, -y2, y1], [y2, 0.0, -y0], [-y1, y0, 0.0]])
    dR[:, 2, :] = sx @ dy - sy @ dx
    return dR


def look_at_pose(p_world_camera: np.ndarray, p_world_target: np.ndarray) -> np.ndarray:
    """Homogeneous T_world_camera (4, 4) of a camera at a point looking at a target."""
    T = np.eye(4)
    T[:3, :3] = camera_rotation(p_world_camera, p_world_target)
    T[:3, 3] = p_world_camera
    return T


def project_point(p_camera: np.ndarray, focal_px: float, width_px: int, height_px: int) -> np.ndarray:
    """Pixel (u, v) of a point in the paper's camera frame (x forward, y left, z up).

    The image u axis points right (-y_C), v points down (-z_C); the principal point is the
    image centre. Raises ValueError for points behind the camera.
    """
    p = np.asarray(p_camera, dtype=float)
    if p[0] <= 0.0:
        raise ValueError("point is behind the camera (x_C <= 0)")
    u = 0.5 * width_px - focal_px * p[1] / p[0]
    v = 0.5 * height_px - focal_px * p[2] / p[0]
    return np.array([u, v])


def project_points(t_camera: np.ndarray, focal_px: float, width_px: int, height_px: int) -> np.ndarray:
    """Pixels (u, v) of points (N, 3) in the camera frame, (N, 2): :func:`project_point` for
    many at once. No check of the depth: the caller masks the points behind the camera (and
    passes them a depth that does not divide by zero)."""
    t = np.atleast_2d(np.asarray(t_camera, dtype=float))
    return np.column_stack(
        [0.5 * width_px - focal_px * t[:, 1] / t[:, 0], 0.5 * height_px - focal_px * t[:, 2] / t[:, 0]]
    )


def pixel_rays(uv: np.ndarray, focal_px: float, width_px: int, height_px: int) -> np.ndarray:
    """Unit rays in the paper's camera frame through image points (u, v), (N, 2) -> (N, 3).

    The inverse of :func:`project_point`: u right, v down, principal point at the centre;
    continuous pixel coordinates (pixel i spans [i, i + 1)).
    """
    uv = np.atleast_2d(np.asarray(uv, dtype=float))
    rays = np.empty((uv.shape[0], 3))
    rays[:, 0] = focal_px
    rays[:, 1] = 0.5 * width_px - uv[:, 0]
    rays[:, 2] = 0.5 * height_px - uv[:, 1]
    return rays / np.linalg.norm(rays, axis=1, keepdims=True)


def ray_frame(axis: np.ndarray) -> np.ndarray:
    """Orthonormal columns (axis, across, up-across) for a unit ``axis``: the first across
    direction is horizontal (axis × z; y where the axis is vertical). Covariances laid along a
    line of sight and across it are built in it."""
    e1 = np.cross(axis, [0.0, 0.0, 1.0])
    n = float(np.linalg.norm(e1))
    e1 = e1 / n if n > 1e-9 else np.array([0.0, 1.0, 0.0])
    return np.column_stack((axis, e1, np.cross(axis, e1)))


def unit(v: np.ndarray, fallback: tuple[float, float, float] = (1.0, 0.0, 0.0)) -> np.ndarray:
    """``v`` / ‖v‖, or ``fallback`` for a vector of (near) zero length."""
    n = float(np.linalg.norm(v))
    return v / n if n > 1e-12 else np.array(fallback, dtype=float)
