"""Headless off-screen rendering of a MuJoCo camera (EGL, then OSMesa).

The backend is chosen at run time, once per process: ``MUJOCO_GL`` if the user set it to
``egl`` or ``osmesa``, else the first of EGL and OSMesa that can create a context (probed in
a subprocess, because PyOpenGL cannot switch platforms once imported). Nothing happens at
import: the choice is made when the first renderer is built.
"""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys
import threading
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache
from typing import Any

import mujoco
import numpy as np
from numpy.typing import ArrayLike

from bve_mj.errors import BveError

__all__ = ["OffscreenRenderer", "RenderError", "add_marker", "gl_backend"]

_DEBIAN = "libegl1 and libgl1 (EGL), or libosmesa6 (OSMesa)"


class RenderError(BveError):
    """No headless OpenGL backend works on this machine."""


def _probe(backend: str) -> bool:
    code = f"from mujoco.{backend} import GLContext\nc = GLContext(16, 16); c.make_current(); c.free()\n"
    env = {k: v for k, v in os.environ.items() if k != "PYOPENGL_PLATFORM"}
    try:
        res = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, timeout=60)
    except (OSError, subprocess.TimeoutExpired):
        return False
    return res.returncode == 0


@cache
def gl_backend() -> str:
    """The headless OpenGL backend this process renders with: "egl" or "osmesa".

    Raises:
        RenderError: naming the Debian packages to install when neither works.
    """
    chosen = os.environ.get("MUJOCO_GL", "").lower().strip()
    if chosen in ("egl", "osmesa"):
        return chosen
    for backend in ("egl", "osmesa"):
        if _probe(backend):
            return backend
    raise RenderError(
        f"no headless OpenGL backend works here (tried EGL and OSMesa); install {_DEBIAN}, "
        "e.g. apt-get install libegl1 libgl1 libosmesa6"
    )


_CONTEXTS: dict[tuple[int, int, int, int], Any] = {}
"""The GL contexts this process renders in: one per thread and image size, kept for the
process's life. A fresh context costs ~0.25 s on its first draw (the software renderer
builds its shaders per context), which every episode paid when each renderer made its own."""


def _context(width: int, height: int) -> Any:
    """This thread's GL context for ``width`` x ``height`` images, made current.

    Keyed by process too: a forked child must not draw in its parent's context."""
    key = (os.getpid(), threading.get_ident(), width, height)
    ctx = _CONTEXTS.get(key)
    if ctx is None:
        backend = gl_backend()
        try:
            if backend == "egl":
                from mujoco.egl import GLContext
            else:
                from mujoco.osmesa import GLContext
            ctx = GLContext(width, height)
            ctx.make_current()
        except Exception as exc:  # the probe passed but this process cannot: say which and why
            raise RenderError(f"cannot create a {backend} context ({exc}); install {_DEBIAN}") from None
        _CONTEXTS[key] = ctx
    else:
        ctx.make_current()
    return ctx


def _make_context(model: mujoco.MjModel, shadows: bool) -> mujoco.MjrContext:
    """The model's render context; without shadows, without the shadow map.

    MuJoCo allocates a ``visual.quality.shadowsize``² depth map (4096² by default) whether
    or not shadows are drawn: ~0.04 s of a ~0.12 s context on a software renderer. Without
    shadows it is never read, so the context is made with none (the model's value is put
    back); the images are the same to the bit.
    """
    quality = model.vis.quality
    kept = quality.shadowsize
    if not shadows:
        quality.shadowsize = 0
    try:
        return mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_100)
    finally:
        quality.shadowsize = kept


@dataclass
class _Shared:
    """A model's render context and the renderers drawing with it."""

    model: mujoco.MjModel  # kept alive while its context is: the id in the key stays its own
    ctx: mujoco.MjrContext
    users: int = 0


_GlKey = tuple[int, int, int, int]
_SHARED: OrderedDict[tuple[int, bool, _GlKey], _Shared] = OrderedDict()
IDLE_CONTEXTS = 2
"""Render contexts kept, per GL context, after their last renderer closed. A model's context
(its meshes and textures uploaded, its buffers) costs ~0.05 s to make on a software
renderer; the episodes of a campaign that share one compiled scene
(:data:`bve_mj.loop.start.KEPT_SCENES`) make it once."""


def _acquire(model: mujoco.MjModel, shadows: bool, gl_key: _GlKey) -> mujoco.MjrContext:
    """The model's render context in the current GL context (made, or the one kept)."""
    key = (id(model), shadows, gl_key)
    entry = _SHARED.get(key)  # its model is this one: kept alive, its id is not reused
    if entry is None:
        entry = _Shared(model, _make_context(model, shadows))
        _SHARED[key] = entry
    _SHARED.move_to_end(key)
    entry.users += 1
    return entry.ctx


def _release(ctx: mujoco.MjrContext, gl_key: _GlKey) -> None:
    """A renderer is done with ``ctx``; idle contexts beyond :data:`IDLE_CONTEXTS` of this GL
    context (which is current) are freed, the least recently used first."""
    entries = list(_SHARED.items())  # a snapshot: a renderer collected meanwhile releases too
    for _, entry in entries:
        if entry.ctx is ctx:
            entry.users -= 1
    idle = [k for k, e in entries if e.users <= 0 and k[2] == gl_key]
    for key in idle[: max(len(idle) - IDLE_CONTEXTS, 0)]:
        if key in _SHARED:
            _SHARED.pop(key).ctx.free()


class OffscreenRenderer:
    """Renders one of a model's cameras into RGB arrays (H, W, 3) uint8.

    Args:
        model: the compiled model (its ``visual.global_.offwidth/offheight`` must be at
            least the requested size).
        width, height: image size [px].
        shadows: shadows cost about 10x per frame on a CPU renderer; off by default.
        hidden_groups: geom groups not drawn (the arm's geoms are group 2).
        blur_sigma_px: a Gaussian blur of every image (a camera's point spread; 0: none).
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        width: int,
        height: int,
        *,
        shadows: bool = False,
        hidden_groups: tuple[int, ...] = (),
        blur_sigma_px: float = 0.0,
    ) -> None:
        if width > model.vis.global_.offwidth or height > model.vis.global_.offheight:
            raise RenderError(
                f"image {width}x{height} exceeds the model's offscreen buffer "
                f"{model.vis.global_.offwidth}x{model.vis.global_.offheight}"
            )
        self._model = model
        self._gl = _context(width, height)
        self._gl_key: _GlKey = (os.getpid(), threading.get_ident(), width, height)
        self._ctx = _acquire(model, shadows, self._gl_key)
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN, self._ctx)
        self._scene = mujoco.MjvScene(model, maxgeom=2000)
        self._scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = shadows
        self._scene.flags[mujoco.mjtRndFlag.mjRND_SKYBOX] = True
        self._option = mujoco.MjvOption()
        for g in hidden_groups:
            self._option.geomgroup[g] = 0
        self._camera = mujoco.MjvCamera()
        self._camera.type = mujoco.mjtCamera.mjCAMERA_FIXED
        self._viewport = mujoco.MjrRect(0, 0, width, height)
        self._rgb = np.empty((height, width, 3), dtype=np.uint8)
        self.width, self.height = width, height
        self._blur = float(blur_sigma_px)

    def _finish(self) -> np.ndarray:
        """The pixels read back, upright, with the camera's blur."""
        mujoco.mjr_readPixels(self._rgb, None, self._viewport, self._ctx)
        image = np.flipud(self._rgb)
        if self._blur > 0.0:
            import cv2

            return cv2.GaussianBlur(image, (0, 0), self._blur)
        return image.copy()

    def render(self, data: mujoco.MjData, camera: str | int) -> np.ndarray:
        """The image of ``camera`` (name or id) for the current ``data`` (kinematics done)."""
        cam_id = camera if isinstance(camera, int) else self._model.camera(camera).id
        self._camera.fixedcamid = cam_id
        self._current()
        mujoco.mjv_updateScene(
            self._model, data, self._option, None, self._camera, mujoco.mjtCatBit.mjCAT_ALL, self._scene
        )
        mujoco.mjr_render(self._viewport, self._scene, self._ctx)
        return self._finish()

    def render_free(
        self,
        data: mujoco.MjData,
        lookat: np.ndarray,
        distance: float,
        azimuth: float,
        elevation: float,
        decorate: Callable[[mujoco.MjvScene], None] | None = None,
    ) -> np.ndarray:
        """An outside view from a free camera (degrees for the angles); ``decorate(scene)``
        may add marker geoms (see :func:`add_marker`) before drawing."""
        cam = mujoco.MjvCamera()
        cam.type = mujoco.mjtCamera.mjCAMERA_FREE
        cam.lookat[:] = lookat
        cam.distance, cam.azimuth, cam.elevation = distance, azimuth, elevation
        self._current()
        mujoco.mjv_updateScene(
            self._model, data, self._option, None, cam, mujoco.mjtCatBit.mjCAT_ALL, self._scene
        )
        if decorate is not None:
            decorate(self._scene)
        mujoco.mjr_render(self._viewport, self._scene, self._ctx)
        return self._finish()

    def _current(self) -> None:
        """This renderer's GL context current and its own offscreen buffer bound (renderers
        of one thread share a context)."""
        if self._ctx is None:
            raise RenderError("the renderer is closed")
        self._gl.make_current()
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN, self._ctx)

    def close(self) -> None:
        """Release this renderer's GL resources (also done when it is garbage-collected).

        Its MjrContext (the model's meshes and textures, its buffers) is kept for the next
        renderer of the same model object, up to :data:`IDLE_CONTEXTS` idle ones, and freed
        in the GL context it was made in; that context stays, for the thread's next renderer."""
        if getattr(self, "_ctx", None) is None:
            return
        self._gl.make_current()
        _release(self._ctx, self._gl_key)
        self._ctx = None

    def __del__(self) -> None:  # pragma: no cover - best effort
        with contextlib.suppress(Exception):
            self.close()


def add_marker(
    scene: mujoco.MjvScene,
    geom_type: mujoco.mjtGeom,
    size: ArrayLike,
    pos: ArrayLike,
    mat: ArrayLike,
    rgba: ArrayLike,
) -> None:
    """Append a decorative geom (not in the model) to a scene about to be drawn."""
    if scene.ngeom >= scene.maxgeom:
        return
    mujoco.mjv_initGeom(
        scene.geoms[scene.ngeom],
        geom_type,
        np.asarray(size, dtype=float),
        np.asarray(pos, dtype=float),
        np.asarray(mat, dtype=float).reshape(9),
        np.asarray(rgba, dtype=np.float32),
    )
    scene.ngeom += 1
