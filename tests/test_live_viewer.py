"""bve-mj episode --viewer: the episode mirrored into MuJoCo's passive viewer (a stand-in
window here: this machine has no display), and a one-line refusal without a display."""

import contextlib
import os
import subprocess
import sys

import mujoco
import numpy as np

from bve_mj.config import Settings, with_overrides
from bve_mj.estimation import Belief
from bve_mj.loop.mujoco import run_mujoco_episode
from bve_mj.reporting.live_viewer import LiveViewer, ellipsoid_geom


class _Window:
    """What launch_passive returns, without a window: a user scene, a lock, sync counts."""

    def __init__(self, model, data):
        self.model, self.data = model, data
        self.user_scn = mujoco.MjvScene(model, maxgeom=64)
        self.synced_times = []
        self.closed = False

    def lock(self):
        return contextlib.nullcontext()

    def is_running(self):
        return not self.closed

    def sync(self):
        self.synced_times.append(float(self.data.time))

    def close(self):
        self.closed = True


def test_the_ellipsoid_is_the_three_sigma_one_of_the_centre():
    A = np.array([[3.0, 1.0, 0.2], [1.0, 2.0, -0.4], [0.2, -0.4, 1.0]]) * 1e-6
    b = Belief(np.array([0.5, -0.1, 0.4]), A)
    half, pos, mat = ellipsoid_geom(b)
    R = mat.reshape(3, 3)
    assert np.allclose(R @ np.diag((half / 3.0) ** 2) @ R.T, A, atol=1e-12)
    assert np.isclose(np.linalg.det(R), 1.0) and np.allclose(pos, b.centre_m)


def test_an_episode_is_played_into_the_viewer_with_its_estimate_and_views():
    windows = []

    def launch(model, data):
        windows.append(_Window(model, data))
        return windows[-1]

    viewer = LiveViewer(launch=launch)
    settings = with_overrides(Settings(), episode={"views": 2})
    episode = run_mujoco_episode(settings, 1, recorder=viewer)
    (w,) = windows
    views = episode.result.views
    assert viewer.close() == len(w.synced_times) > len(views)  # during the moves, and at each view
    assert w.closed and np.ptp(w.synced_times) > 0.0  # synced as the simulation ran
    assert w.user_scn.ngeom == 1 + len(views)  # the ellipsoid and a dot per view
    final = episode.result.final_claim  # what the episode claims, not its bound
    assert final.sigma_max_m < 0.9 * views[-1].belief.sigma_max_m
    ell = w.user_scn.geoms[0]
    assert ell.type == mujoco.mjtGeom.mjGEOM_ELLIPSOID
    assert np.allclose(ell.pos, final.centre_m)
    assert np.isclose(max(ell.size), 3.0 * final.sigma_max_m, rtol=1e-3)
    assert np.allclose(w.user_scn.geoms[len(views)].pos, views[-1].p_world_camera)


def test_without_a_display_the_viewer_is_refused_in_one_line():
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    r = subprocess.run(
        [sys.executable, "-m", "bve_mj.cli", "episode", "--viewer"], capture_output=True, text=True, env=env
    )
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "viewer" in lines[0] and "DISPLAY" in lines[0], r.stderr
