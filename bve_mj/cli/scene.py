"""``bve-mj scene``: an episode's greenhouse as an MJCF folder to open in MuJoCo's viewer;
``bve-mj draw-scenes``: scenario files of configurations drawn at random."""

from __future__ import annotations

import argparse

from bve_mj.cli.args import EXIT_OK, int_arg

__all__ = ["cmd_draw_scenes", "cmd_scene"]


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


def cmd_draw_scenes(args: argparse.Namespace) -> int:
    from bve_mj.campaigns.drawn_scenes import write_drawn_scenes

    count = int_arg("count", args.count, 1) or 1
    seed = int_arg("seed", args.seed, 0) or 0
    paths = write_drawn_scenes(args.out, count, seed)
    print(f"bve-mj draw-scenes: {count} configurations (seed {seed}) written to {paths[0].parent}")
    for path in paths:
        print(f"  {path.name}: {path.read_text(encoding='utf-8').splitlines()[0].lstrip('# ')}")
    print(f"run them: bve-mj scenarios --dir {paths[0].parent} --seeds 4")
    return EXIT_OK
