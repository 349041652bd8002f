"""``bve-mj episode --viewer``: the episode played live in MuJoCo's passive viewer.

The viewer shows the episode's own simulation (the same ``MjModel`` and ``MjData``): the arm
moving under the position controller, the crop, the fruit. Drawn on top as user geoms
(visual only): the estimate's 3σ ellipsoid (magenta) and the camera's position at every view
(cyan). The window is synced at most ``fps`` times a second of wall time while the arm
moves, and at every view. Closing the window does not stop the episode; it runs to its end.

Needs a display (``DISPLAY`` or ``WAYLAND_DISPLAY``): :func:`require_display` says why not
in one line (the command exits 2).
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import mujoco
import numpy as np

from bve_mj.errors import ConfigError
from bve_mj.estimation.belief import Belief
from bve_mj.estimation.claim_shape import GAUSSIAN, ClaimShape

if TYPE_CHECKING:
    from bve_mj.loop.records import ViewRecord
    from bve_mj.sim.mujoco_world import MujocoWorld

__all__ = ["LiveViewer", "ellipsoid_geom", "require_display"]

_ESTIMATE_RGBA = np.array([0.9, 0.2, 0.9, 0.45], dtype=np.float32)
_VIEW_RGBA = np.array([0.1, 0.8, 0.9, 1.0], dtype=np.float32)
_VIEW_RADIUS_M = 0.006


def require_display(option: str = "viewer") -> None:
    """Raise a one-line :class:`ConfigError` when no display is there for a window."""
    if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise ConfigError(
            option,
            True,
            "a display: neither DISPLAY nor WAYLAND_DISPLAY is set (record with --video instead)",
        )


def ellipsoid_geom(belief: Belief, sigmas: float = 3.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(half axes [m] (3,), centre (3,), rotation row-major (9,)) of the ``sigmas`` ellipsoid of
    the belief's centre, as ``mujoco.mjv_initGeom`` takes them for an ellipsoid."""
    cov = belief.position.cov
    w, V = np.linalg.eigh(0.5 * (cov + cov.T))
    if np.linalg.det(V) < 0:
        V[:, 0] = -V[:, 0]  # a rotation, not a reflection
    half = sigmas * np.sqrt(np.maximum(w, 0.0))
    return np.maximum(half, 1e-4), belief.centre_m.astype(float).copy(), V.reshape(-1).astype(float)


def _launch_passive(model: mujoco.MjModel, data: mujoco.MjData) -> Any:
    import mujoco.viewer

    return mujoco.viewer.launch_passive(model, data, show_left_ui=False, show_right_ui=False)


class LiveViewer:
    """Plays an episode in MuJoCo's passive viewer (module docstring); an episode recorder
    (``attach``, ``on_step``, ``on_view``, ``close``) for :func:`bve_mj.loop.mujoco.
    run_mujoco_episode`.

    Args:
        fps: the most window syncs per second of wall time while the arm moves.
        launch: opens the viewer on (model, data) (default: ``mujoco.viewer.launch_passive``).
    """

    def __init__(
        self, fps: float = 60.0, launch: Callable[[mujoco.MjModel, mujoco.MjData], Any] | None = None
    ):
        if not fps > 0:
            raise ConfigError("fps", fps, "a number > 0")
        self.fps = float(fps)
        self._launch = launch or _launch_passive
        self.handle: Any = None
        self._belief: Belief | None = None
        self._shape: ClaimShape = GAUSSIAN
        self._views: list[np.ndarray] = []
        self._last_sync = -np.inf
        self.syncs = 0

    def attach(self, world: MujocoWorld, prior: Belief, shape: ClaimShape = GAUSSIAN) -> None:
        self.handle = self._launch(world.model, world.data)
        self._shape = shape
        self._belief = prior
        self._draw()
        self._sync()

    def on_step(self, sim_time: float) -> None:
        if self.handle is not None and time.perf_counter() - self._last_sync >= 1.0 / self.fps:
            self._sync()

    def on_view(self, record: ViewRecord) -> None:
        self._belief = self._shape.claim(
            record.belief, record.sensor_cov
        )  # what the view claims: its belief is the bound
        self._views.append(np.asarray(record.p_world_camera, dtype=float).copy())
        self._draw()
        self._sync()

    def close(self) -> int:
        """Close the window (if the user has not); returns the number of syncs."""
        if self.handle is not None:
            self.handle.close()
            self.handle = None
        return self.syncs

    def _sync(self) -> None:
        if self.handle is None or not self.handle.is_running():
            return
        self.handle.sync()
        self.syncs += 1
        self._last_sync = time.perf_counter()

    def _draw(self) -> None:
        """The estimate's ellipsoid and a dot at every view, as the viewer's user geoms."""
        if self.handle is None:
            return
        scn = self.handle.user_scn
        with self.handle.lock():
            scn.ngeom = 0
            if self._belief is not None and scn.maxgeom > 0:
                size, pos, mat = ellipsoid_geom(self._belief)
                mujoco.mjv_initGeom(
                    scn.geoms[0], mujoco.mjtGeom.mjGEOM_ELLIPSOID, size, pos, mat, _ESTIMATE_RGBA
                )
                scn.ngeom = 1
            for p in self._views[-(scn.maxgeom - scn.ngeom) :] if scn.maxgeom > scn.ngeom else []:
                mujoco.mjv_initGeom(
                    scn.geoms[scn.ngeom], mujoco.mjtGeom.mjGEOM_SPHERE, np.full(3, _VIEW_RADIUS_M), p,
                    np.eye(3).reshape(-1), _VIEW_RGBA,
                )  # fmt: skip
                scn.ngeom += 1
