"""Scene files drawn at random: greenhouse configurations nobody developed on.

Each scenario file of the suite fixes a configuration (fruit type, truss layout, ripeness,
light, sensor) and every seed draws a scene within it (plants, leaves, sun, fruit sizes).
The project is judged on configurations it has not seen, so the configurations are drawn
too (``bve-mj draw-scenes``): each file one draw from the scene space below, written as an
ordinary scenario file that ``bve-mj scenarios --dir`` runs and ``bve-mj calibrate --dir``
calibrates over. The same ``seed`` and ``count`` write the same files.

The scene space (every setting within what :class:`~bve_mj.config.SceneConfig` validates,
the ranges from ``docs/greenhouse.md`` where it gives them):

=========================  ===============================================================
fruit type                 cherry, cocktail, round, beefsteak or plum, equally likely
fruit per truss            the type's range (``FRUIT_TYPE_PER_TRUSS``): cherry 12-25,
                           cocktail 8-14, round 4-8, beefsteak 2-5, plum 4-8 (uniform)
target                     any fruit of its truss (uniform), red
truss layout               chain or cluster, equally likely
trusses, plants            1-4, 1-6
ripeness of the truss      drawn by the scene (half the files), or each fruit's class
                           drawn uniformly, the target red (the other half)
other trusses              unripe or mixed, equally likely
leaf density               uniform 0-2.5 (1 = a leaf every 5-8 cm of stem)
sun                        half the files: azimuth window of 0-60° anywhere, elevation
                           window of 0-20° within 5-85°, intensity window of 0-0.3 within
                           0.1-1.0; the others the defaults
sky                        uniform 0.2-1.0 in a third of the files, else the default
backlight                  uniform 0.2-1.2 in 30% of the files
headlight (a flash)        20% of the files
shadows                    10% of the files (several times the render cost)
target height, sideways    a 0.10 m window within 0.0-0.45 m (30% of the files), and
                           within ±0.3 m (20%); else the defaults
sensor                     30% of the files: image noise 0-4 levels, focal error 0-1.5%,
                           principal point 0-3 px, encoder noise 0 or 0.0004 rad
=========================  ===============================================================
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any, get_args

import numpy as np

from bve_mj.config.fields import FruitType, RipenessName
from bve_mj.config.scene import FRUIT_TYPE_PER_TRUSS
from bve_mj.errors import ConfigError

__all__ = ["MAX_DRAWN", "draw_scene", "scene_toml", "write_drawn_scenes"]

MAX_DRAWN = 10_000
"""The most configurations one call writes."""


def _window(rng: np.random.Generator, low: float, high: float, width: float, digits: int = 3) -> list[float]:
    """[a, a + width] within [low, high], a uniform."""
    a = float(rng.uniform(low, high - width))
    return [round(a, digits), round(a + width, digits)]


def draw_scene(rng: np.random.Generator) -> tuple[str, dict[str, dict[str, Any]]]:
    """One configuration from the scene space (module docstring): a one-line description
    and the settings' sections (``scene``, and ``sensor`` when drawn)."""
    fruit_type = str(rng.choice(get_args(FruitType)))
    k = int(rng.integers(FRUIT_TYPE_PER_TRUSS[fruit_type][0], FRUIT_TYPE_PER_TRUSS[fruit_type][1] + 1))
    target = int(rng.integers(k))
    layout = str(rng.choice(["chain", "cluster"]))
    scene: dict[str, Any] = {
        "fruit_type": fruit_type,
        "fruit_per_truss": k,
        "target_index": target,
        "truss_layout": layout,
        "trusses": int(rng.integers(1, 5)),
        "plants": int(rng.integers(1, 7)),
        "leaf_density": round(float(rng.uniform(0.0, 2.5)), 2),
        "other_trusses_ripeness": str(rng.choice(["unripe", "mixed"])),
    }
    said = [f"{k} {fruit_type} tomatoes in a {layout}, the target fruit {target + 1} from the stem."]
    if rng.random() < 0.5:
        classes = get_args(RipenessName)
        ripeness = [str(rng.choice(classes)) for _ in range(k)]
        ripeness[target] = "red"
        scene["ripeness"] = ripeness
        said.append(f"{ripeness.count('red')} red.")
    if rng.random() < 0.5:
        scene["sun_azimuth_deg"] = _window(rng, -180.0, 360.0, float(rng.uniform(0.0, 60.0)), 1)
        scene["sun_elevation_deg"] = _window(rng, 5.0, 85.0, float(rng.uniform(0.0, 20.0)), 1)
        scene["sun_intensity"] = _window(rng, 0.1, 1.0, float(rng.uniform(0.0, 0.3)), 2)
        said.append(f"sun at {scene['sun_elevation_deg'][0]:.0f}° elevation.")
    if rng.random() < 1.0 / 3.0:
        scene["sky_intensity"] = round(float(rng.uniform(0.2, 1.0)), 2)
    if rng.random() < 0.3:
        scene["backlight"] = round(float(rng.uniform(0.2, 1.2)), 2)
        said.append("backlit.")
    if rng.random() < 0.2:
        scene["headlight"] = True
        said.append("a flash on the camera.")
    if rng.random() < 0.1:
        scene["shadows"] = True
        said.append("hard shadows.")
    if rng.random() < 0.3:
        scene["target_z_m"] = _window(rng, 0.0, 0.45, 0.10)
    if rng.random() < 0.2:
        scene["target_y_m"] = _window(rng, -0.3, 0.3, 0.10)
    sections: dict[str, dict[str, Any]] = {"scene": scene}
    if rng.random() < 0.3:
        sections["sensor"] = {
            "image_noise_std": round(float(rng.uniform(0.0, 4.0)), 1),
            "focal_error_rel": round(float(rng.uniform(0.0, 0.015)), 4),
            "principal_point_error_px": round(float(rng.uniform(0.0, 3.0)), 1),
            "encoder_noise_rad": float(rng.choice([0.0, 4e-4])),
        }
        said.append("sensor noise and calibration error.")
    return " ".join(said), sections


def _literal(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ValueError(f"not a finite number: {value}")
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_literal(v) for v in value) + "]"
    raise TypeError(f"no TOML literal for {type(value).__name__}")


def scene_toml(description: str, sections: Mapping[str, Mapping[str, Any]]) -> str:
    """A scenario file: ``description`` as its leading comment, then each section's keys."""
    lines = [f"# {description}"]
    for name, keys in sections.items():
        lines.append(f"[{name}]")
        lines += [f"{key} = {_literal(value)}" for key, value in keys.items()]
    return "\n".join(lines) + "\n"


def write_drawn_scenes(out: str | Path, count: int, seed: int) -> list[Path]:
    """Draw ``count`` configurations (seed ``seed``) and write each as ``drawn_<seed>_<i>.toml``
    in the folder ``out`` (made if missing). Nothing is overwritten: a folder that already
    holds any of these files is refused before anything is written.

    Raises:
        ConfigError: a bad ``count`` or ``seed``, or ``out`` not a folder, or holding them."""
    from bve_mj.atomic import write_text_atomic
    from bve_mj.config import settings_from_dict
    from bve_mj.config.settings import tomllib

    for name, value, lo, hi in (("count", count, 1, MAX_DRAWN), ("seed", seed, 0, 2**63 - 1)):
        if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
            raise ConfigError(name, value, f"an integer in [{lo}, {hi}]")
    folder = Path(out)
    if folder.exists() and not folder.is_dir():
        raise ConfigError("out", str(out), "a folder (this is a file)")
    digits = len(str(count - 1))
    paths = [folder / f"drawn_{seed}_{i:0{digits}d}.toml" for i in range(count)]
    taken = [p.name for p in paths if p.exists()]
    if taken:
        raise ConfigError("out", str(out), f"a folder without {taken[0]} (nothing is overwritten)")
    rng = np.random.default_rng(np.random.SeedSequence(seed))
    texts = []
    for i in range(count):
        description, sections = draw_scene(rng)
        text = scene_toml(f"Drawn scene {i} of seed {seed}: {description}", sections)
        settings_from_dict(tomllib.loads(text))  # each draw is a valid scenario, read as written
        texts.append(text)
    try:
        folder.mkdir(parents=True, exist_ok=True)
        for path, text in zip(paths, texts, strict=True):
            write_text_atomic(path, text)
    except OSError as exc:
        raise ConfigError("out", str(out), f"a folder this user can write ({exc.strerror})") from None
    return paths
