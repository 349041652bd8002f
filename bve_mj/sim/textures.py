"""Procedural textures of the greenhouse, made by this project from numbers (no image files).

Fruit skins are cube textures: MuJoCo maps a cube texture onto an ellipsoid by the direction
from its centre in the geom frame (OpenGL cube-map convention, faces +x, -x, +y, -y, +z, -z;
z is up, the stem end). A skin is a function of that direction: the ripe colour spreads from
the blossom end (bottom) upwards over the share of the surface that is no longer green (the
USDA classes: green 0 %, breaker <= 10 %, turning 10-30 %, pink 30-60 %, light red 60-90 %,
red > 90 %), with a blotchy, slightly star-shaped front, the shoulder at the calyx greener,
and a little variation over the surface.

Everything is built in memory at run time (the scene does not need the repository's
``assets/``); ``python -m bve_mj.sim.textures [DIR]`` writes the same textures as PNGs
(default ``assets/textures/``) for people to look at.
"""

from __future__ import annotations

import math
import sys
from functools import cache
from pathlib import Path

import numpy as np

__all__ = [
    "RIPENESS_STAGES",
    "cube_directions",
    "foliage_texture",
    "fruit_texture",
    "ground_texture",
    "ripeness_stage",
    "skin_colour",
    "write_textures",
]

RIPENESS_STAGES: dict[str, tuple[float, float]] = {
    "green": (0.0, 0.0),
    "breaker": (0.03, 0.10),
    "turning": (0.12, 0.30),
    "pink": (0.32, 0.58),
    "light_red": (0.62, 0.88),
    "red": (0.95, 1.0),
}
"""Share of the surface no longer green, per USDA ripeness class (a range to draw from)."""

# colour of the ripening skin at each stage (stage, linear RGB): tan blush, yellow-orange,
# pink (pale: not the saturated red of ripe fruit), light red, deep red
_RIPE_PALETTE = np.array(
    [
        (0.00, 0.80, 0.74, 0.45),
        (0.10, 0.88, 0.70, 0.38),
        (0.25, 0.93, 0.60, 0.30),
        (0.35, 0.93, 0.66, 0.45),
        (0.45, 0.93, 0.64, 0.58),
        (0.60, 0.91, 0.50, 0.40),
        (0.75, 0.90, 0.32, 0.22),
        (0.93, 0.79, 0.11, 0.07),
        (1.00, 0.74, 0.08, 0.05),
    ]
)
_GREEN = np.array([0.50, 0.64, 0.27])  # mature green
_GREEN_SHOULDER = np.array([0.33, 0.49, 0.16])  # darker green shoulder at the calyx
_GREEN_BLOSSOM = np.array([0.62, 0.71, 0.40])  # lighter blossom end
_YELLOWED = np.array([0.64, 0.68, 0.28])  # the green part as the fruit colours (still yellow-green)
_SHOULDER_RIPE = np.array([0.86, 0.42, 0.13])  # the last of the shoulder on a red fruit
_SCAR = np.array([0.45, 0.38, 0.20])  # blossom-end scar


def ripeness_stage(ripeness: str, u: float = 0.5) -> float:
    """The share of the surface no longer green for class ``ripeness`` at ``u`` in [0, 1] of
    its range (``orange``, the legacy name, is a turning fruit)."""
    lo, hi = RIPENESS_STAGES["turning" if ripeness == "orange" else ripeness]
    return lo + (hi - lo) * float(np.clip(u, 0.0, 1.0))


def skin_colour(stage: float) -> np.ndarray:
    """The colour of the ripening skin at ``stage`` (linear RGB in [0, 1], (3,))."""
    p = _RIPE_PALETTE
    return np.array([np.interp(stage, p[:, 0], p[:, k]) for k in (1, 2, 3)])


def cube_directions(width: int) -> np.ndarray:
    """Unit directions of the texel centres of a cube texture, (6, width, width, 3).

    Faces in MuJoCo's order (+x, -x, +y, -y, +z, -z); within a face, rows run along the
    OpenGL cube map's t and columns along its s coordinate (checked against renders).
    """
    c = (np.arange(width) + 0.5) / width * 2.0 - 1.0
    s, t = np.meshgrid(c, c)
    one = np.ones_like(s)
    faces = [
        np.stack([one, -t, -s], -1),
        np.stack([-one, -t, s], -1),
        np.stack([s, one, t], -1),
        np.stack([s, -one, -t], -1),
        np.stack([s, -t, one], -1),
        np.stack([-s, -t, -one], -1),
    ]
    d = np.stack(faces)
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def _smooth_noise(d: np.ndarray, rng: np.random.Generator, waves: int, lo: float, hi: float) -> np.ndarray:
    """A smooth random field on directions ``d`` (..., 3): a sum of plane waves, std ~1."""
    k = rng.normal(size=(waves, 3))
    k *= (rng.uniform(lo, hi, waves) / np.linalg.norm(k, axis=1))[:, None]
    phase = rng.uniform(0.0, 2.0 * math.pi, waves)
    out = np.cos(d @ k.T + phase).sum(axis=-1)
    return out / math.sqrt(waves / 2.0)


def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


@cache
def fruit_texture(stage: float, seed: int = 0, width: int = 64) -> np.ndarray:
    """A tomato skin as a cube texture, (6 * width, width, 3) uint8 (read-only, cached).

    Args:
        stage: share of the surface no longer green, 0 (green) to 1 (red); the colour
            spreads from the blossom end (-z) upwards, so the front sits where the area
            below it is ``stage``: z = 2 stage - 1 (Archimedes: a sphere's area is uniform
            in z), made blotchy by smooth noise and a faint star along the locules.
        seed: the pattern's variation (noise); the same arguments give the same texture.
    """
    rng = np.random.default_rng([seed, round(stage * 1000), width])
    d = cube_directions(width)
    z = d[..., 2]
    phi = np.arctan2(d[..., 1], d[..., 0])
    blotch = _smooth_noise(d, rng, 12, 2.0, 6.0)
    star = np.cos(rng.integers(5, 7) * phi + rng.uniform(0, 2 * math.pi)) * (1.0 - z) / 2.0
    irregular = float(np.clip(5.0 * stage, 0.3, 1.0))  # a small blush is a small, even cap
    front = 2.0 * stage - 1.0 - 0.015 + irregular * (0.10 * blotch + 0.05 * star)
    if stage <= 0.0:
        ripe_w = np.zeros_like(z)
    else:
        ripe_w = _smoothstep((front - z) / 0.16 + 0.5)
        ripe_w = np.where(stage >= 0.999, 1.0, ripe_w)
    # the ripe colour: further along towards the blossom end than at the front
    local = np.clip(stage + 0.12 * np.clip(front - z, 0.0, 1.0), 0.0, 1.0)
    ripe = np.stack([np.interp(local, _RIPE_PALETTE[:, 0], _RIPE_PALETTE[:, k]) for k in (1, 2, 3)], -1)
    # the green part: darker shoulder, lighter blossom end, yellowing as the fruit colours
    green = _GREEN + (_GREEN_SHOULDER - _GREEN) * _smoothstep((z - 0.35) / 0.5)[..., None]
    green = green + (_GREEN_BLOSSOM - _GREEN) * _smoothstep((-z - 0.4) / 0.5)[..., None]
    green = green + (_YELLOWED - green) * min(1.0, 1.6 * stage)
    green = green + (_SHOULDER_RIPE - green) * float(np.clip((stage - 0.92) / 0.05, 0.0, 1.0))
    rgb = green + (ripe - green) * ripe_w[..., None]
    # variation over the surface: smooth brightness, a faint hue wobble, fine speckle
    shade = 1.0 + 0.045 * _smooth_noise(d, rng, 10, 3.0, 9.0)
    wobble = 0.02 * _smooth_noise(d, rng, 8, 2.0, 7.0)
    rgb = rgb * shade[..., None]
    rgb[..., 1] += wobble * rgb[..., 1]
    rgb = rgb * (1.0 + 0.015 * rng.standard_normal(z.shape))[..., None]
    scar = _smoothstep((-z - 0.994) / 0.004)[..., None]
    rgb = rgb + (_SCAR - rgb) * scar
    out = np.clip(np.rint(rgb * 255.0), 0, 255).astype(np.uint8).reshape(6 * width, width, 3)
    out.setflags(write=False)
    return out


def _splat_leaves(img: np.ndarray, rng: np.random.Generator, count: int, size: tuple[float, float]) -> None:
    """Draw ``count`` leaflet-shaped ellipses of random greens into ``img`` (tiling, in place)."""
    n = img.shape[0]
    yy, xx = np.mgrid[-24:25, -24:25].astype(float)
    for _ in range(count):
        a = rng.uniform(*size)
        b = a * rng.uniform(0.35, 0.55)
        th = rng.uniform(0.0, math.pi)
        u = xx * math.cos(th) + yy * math.sin(th)
        v = -xx * math.sin(th) + yy * math.cos(th)
        inside = (u / a) ** 2 + (v / b) ** 2 <= 1.0
        g = rng.uniform(0.55, 1.25)
        colour = np.array([0.16, 0.36, 0.11]) * g + rng.normal(0.0, 0.015, 3)
        # light from above: the upper half of each leaflet a little brighter, a paler midrib
        lit = 1.0 + 0.12 * np.clip(-yy / 24.0, -1.0, 1.0)
        rib = (np.abs(v) < 0.7) & inside
        cx, cy = rng.integers(0, n, 2)
        rows = (cy + yy.astype(int)) % n
        cols = (cx + xx.astype(int)) % n
        patch = colour[None, None, :] * lit[..., None]
        patch = np.where(rib[..., None], patch * 1.25, patch)
        img[rows[inside], cols[inside]] = patch[inside]


@cache
def foliage_texture(seed: int = 0, size: int = 256) -> np.ndarray:
    """A tiling picture of dense tomato foliage (far rows, the canopy), (size, size, 3) uint8."""
    rng = np.random.default_rng([seed, size, 7])
    img = np.empty((size, size, 3))
    img[:] = (0.05, 0.12, 0.04)
    # a few stems and petioles behind the leaves
    for _ in range(6):
        x0 = rng.integers(0, size)
        slope = rng.uniform(-0.15, 0.15)
        for y in range(size):
            x = int(x0 + slope * y) % size
            img[y, x : x + 3] = (0.28, 0.38, 0.16)
    _splat_leaves(img, rng, size * 3, (5.0, 14.0))
    img *= 1.0 + 0.05 * rng.standard_normal((size, size, 1))
    out = np.clip(np.rint(img * 255.0), 0, 255).astype(np.uint8)
    out.setflags(write=False)
    return out


@cache
def ground_texture(kind: str = "foil", size: int = 128) -> np.ndarray:
    """Floor cover, (size, size, 3) uint8: ``foil`` (white ground foil with soft folds) or
    ``concrete`` (the central path)."""
    rng = np.random.default_rng([size, 11 if kind == "foil" else 13])
    y, x = np.mgrid[0:size, 0:size] / size * 2.0 * math.pi
    folds = np.zeros((size, size))
    for _ in range(6):  # tiling waves: integer frequencies
        fx, fy = rng.integers(-4, 5, 2)
        folds += np.cos(fx * x + fy * y + rng.uniform(0, 2 * math.pi))
    if kind == "foil":
        base = np.array([0.86, 0.87, 0.85])
        img = base * (1.0 + 0.03 * folds / 2.5)[..., None]
        dirt = rng.random((size, size)) < 0.004
        img[dirt] *= 0.8
    else:
        base = np.array([0.60, 0.60, 0.58])
        img = base * (1.0 + 0.04 * folds / 2.5 + 0.05 * rng.standard_normal((size, size)))[..., None]
    out = np.clip(np.rint(img * 255.0), 0, 255).astype(np.uint8)
    out.setflags(write=False)
    return out


def write_textures(folder: str | Path = "assets/textures") -> list[Path]:
    """Write the textures as PNGs into ``folder`` (for people to look at) and return the paths:
    one strip of the six cube faces per ripeness class (+x, -x, +y, -y, +z top, -z bottom),
    the foliage and the floor covers."""
    import imageio.v2 as imageio  # optional at run time: only this writer needs it

    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for name in RIPENESS_STAGES:
        tex = fruit_texture(ripeness_stage(name), 0)
        w = tex.shape[1]
        strip = np.concatenate([tex[i * w : (i + 1) * w] for i in range(6)], axis=1)
        path = out / f"tomato_{name}.png"
        imageio.imwrite(path, strip)
        written.append(path)
    for name, img in (
        ("foliage", foliage_texture()),
        ("ground_foil", ground_texture("foil")),
        ("ground_concrete", ground_texture("concrete")),
    ):
        path = out / f"{name}.png"
        imageio.imwrite(path, img)
        written.append(path)
    return written


def main(argv: list[str] | None = None) -> int:
    """``python -m bve_mj.sim.textures [DIR]``: regenerate the PNGs (default assets/textures)."""
    args = sys.argv[1:] if argv is None else argv
    for path in write_textures(args[0] if args else "assets/textures"):
        print(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
