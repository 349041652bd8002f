"""The greenhouse of an episode as an MJCF folder people can open (``bve-mj scene``).

:func:`episode_scene` builds the scene :func:`~bve_mj.loop.start.start_episode` builds for the
same settings and seed: the settings resolved for the MuJoCo world, and the scene drawn from
the first stream ``SeedSequence(seed)`` spawns (a test holds the two equal).
:func:`write_episode_scene` writes it with :func:`bve_mj.sim.mjcf.write_mjcf_folder`.
"""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np

from bve_mj.config import Settings
from bve_mj.loop.mujoco import episode_settings
from bve_mj.robot import arm_kinematics
from bve_mj.sim.mjcf import MANIFEST, check_mjcf_folder, write_mjcf_folder
from bve_mj.sim.scene import build_scene
from bve_mj.sim.scene_model import SceneInfo, fruit_geom_name

__all__ = ["episode_scene", "write_episode_scene"]


def episode_scene(settings: Settings, seed: int) -> tuple[mujoco.MjSpec, SceneInfo]:
    """The scene's spec and ground truth of the episode with ``settings`` and ``seed``."""
    s = episode_settings(settings)
    scene_ss = np.random.SeedSequence(seed).spawn(5)[0]  # start_episode's scene stream
    kin = arm_kinematics(s.robot.name, s.robot.limit_set)
    return build_scene(kin, s.scene, np.random.default_rng(scene_ss), s.camera)


def write_episode_scene(
    settings: Settings, seed: int, folder: str | Path, config: str | None = None
) -> tuple[list[Path], mujoco.MjModel, SceneInfo]:
    """Write the episode's scene into ``folder`` (see :func:`bve_mj.sim.mjcf.write_mjcf_folder`
    for what is written and which folders are refused); ``config`` names the settings file in
    the notes. Returns the paths written, the compiled scene and its ground truth."""
    check_mjcf_folder(folder)  # a folder it may not write to fails before the scene is built
    spec, info = episode_scene(settings, seed)
    model = spec.compile()
    target = info.target
    note = (
        f"The greenhouse of the bve_mj episode with seed {seed} and "
        + (f"the settings of {Path(config).name}" if config else "the default settings")
        + f" (bve_mj {_version()}), written by bve-mj scene (its {MANIFEST} says how); the target "
        f"is the geom {fruit_geom_name(target.name)}. Open it in MuJoCo's viewer: "
        f"python -m mujoco.viewer, with this file as its mjcf."
    )
    about: dict[str, object] = {
        "command": f"bve-mj scene --seed {seed}" + (f" --config {config}" if config else ""),
        "seed": seed,
        "config": config,
        "bve_mj": _version(),
        "mujoco": mujoco.__version__,
        "target": {
            "name": target.name,
            "centre_m": [float(x) for x in target.centre_m],
            "radius_m": float(target.radius_m),
            "colour": target.colour,
        },
        "fruits": len(info.fruits),
    }
    return write_mjcf_folder(spec, folder, note, about), model, info


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("bve_mj")
    except PackageNotFoundError:  # pragma: no cover (run from a source tree, not installed)
        return "unknown (not installed)"
