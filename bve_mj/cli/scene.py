"""``bve-mj scene``: an episode's greenhouse as an MJCF folder to open in MuJoCo's viewer."""

from __future__ import annotations

import argparse

from bve_mj.cli.args import EXIT_OK, int_arg

__all__ = ["cmd_scene"]


def cmd_scene(args: argparse.Namespace) -> int:
    from bve_mj.config import Settings, load_settings
    from bve_mj.loop.scene_file import write_episode_scene

    seed = int_arg("seed", args.seed, 0) or 0
    settings = load_settings(args.config) if args.config else Settings()
    written, model, info = write_episode_scene(settings, seed, args.out, args.config)
    scene = written[0]
    t = info.target
    print(
        f"bve-mj scene: seed {seed}{f', settings {args.config}' if args.config else ''}: "
        f"{model.nbody} bodies, {model.ngeom} geoms, {model.nmesh} meshes, {model.ntex} textures, "
        f"{len(info.fruits)} fruit; the target ({t.colour}, r = {1e3 * t.radius_m:.1f} mm) at "
        f"({', '.join(f'{x:.3f}' for x in t.centre_m)}) m"
    )
    for path in written:
        print(f"wrote {path} ({path.stat().st_size / 1e3:.0f} kB)")
    print(f"open it: python -m mujoco.viewer --mjcf={scene}")
    return EXIT_OK
