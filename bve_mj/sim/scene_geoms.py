"""The crop's MuJoCo bodies: stems, compound leaves, fruit with their skins, and the truss's
rachis, pedicels and calyces."""

from __future__ import annotations

import mujoco
import numpy as np

from bve_mj.sim import plants
from bve_mj.sim.clearance import _inside_fruit
from bve_mj.sim.crop import _Truss
from bve_mj.sim.scene_model import _SKIN_PX, _TEXTURE_VARIANTS, _UP, Fruit, fruit_geom_name
from bve_mj.sim.textures import fruit_texture, ripeness_stage

__all__: list[str] = []  # used by the other modules of this package only


# --------------------------------------------------------------------------- MjSpec assembly
def _add_mesh_geom(
    spec: mujoco.MjSpec,
    name: str,
    parts: plants.MeshParts | tuple[np.ndarray, np.ndarray],
    rgba: tuple[float, ...] | np.ndarray,
    material: str = "",
) -> None:
    verts, faces = parts.arrays() if isinstance(parts, plants.MeshParts) else parts
    mesh = spec.add_mesh(
        name=f"{name}_mesh", uservert=verts.ravel().tolist(), userface=faces.ravel().tolist()
    )
    mesh.inertia = mujoco.mjtMeshInertia.mjMESH_INERTIA_SHELL
    mesh.maxhullvert = 4
    spec.worldbody.add_geom(
        name=name,
        type=mujoco.mjtGeom.mjGEOM_MESH,
        meshname=f"{name}_mesh",
        rgba=list(rgba),
        material=material,
        contype=0,
        conaffinity=0,
        group=1,
    )


def _skin_material(spec: mujoco.MjSpec, fruit: Fruit, made: set[str]) -> str:
    colour = "turning" if fruit.colour == "orange" else fruit.colour
    lo, hi = ripeness_stage(colour, 0.0), ripeness_stage(colour, 1.0)
    u = 0.5 if hi <= lo else (fruit.skin_stage - lo) / (hi - lo)
    variant = int(np.clip(round(u * (_TEXTURE_VARIANTS - 1)), 0, _TEXTURE_VARIANTS - 1))
    name = f"skin_{colour}_{variant}"
    if name not in made:
        stage = ripeness_stage(colour, variant / max(_TEXTURE_VARIANTS - 1, 1))
        tex = fruit_texture(round(stage, 3), variant, _SKIN_PX)
        spec.add_texture(
            name=name,
            type=mujoco.mjtTexture.mjTEXTURE_CUBE,
            width=_SKIN_PX,
            height=6 * _SKIN_PX,
            nchannel=3,
            data=tex.ravel().tolist(),
        )
        mat = spec.add_material(name=name, specular=0.6, shininess=0.85, reflectance=0.0)
        mat.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = name
        made.add(name)
    return name


def _add_fruit(
    spec: mujoco.MjSpec, fruit: Fruit, made: set[str], rng: np.random.Generator
) -> plants.MeshParts:
    """The flesh geom; returns the calyx mesh parts."""
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, fruit.rotation.reshape(9))
    tint = rng.uniform(0.96, 1.02)
    spec.worldbody.add_geom(
        name=fruit_geom_name(fruit.name),
        type=mujoco.mjtGeom.mjGEOM_ELLIPSOID,
        size=list(fruit.semi_axes_m),
        pos=list(fruit.centre_m),
        quat=list(q),
        material=_skin_material(spec, fruit, made),
        rgba=[min(1.0, tint), min(1.0, tint * rng.uniform(0.98, 1.02)), min(1.0, tint), 1.0],
        contype=0,
        conaffinity=0,
        group=1,
    )
    parts = plants.MeshParts()
    sepal = float(np.clip(0.55 * fruit.radius_m + 0.006, 0.008, 0.030))
    parts.extend(plants.calyx(fruit.top_m, fruit.rotation, fruit.semi_axes_m, sepal, rng))
    return parts


def _truss_parts(truss: _Truss, rng: np.random.Generator) -> plants.MeshParts:
    """Peduncle, rachis and pedicels (with their knuckles) of a truss as tubes."""
    parts = plants.MeshParts()
    fruits = truss.fruits
    small = float(np.clip(fruits[0].radius_m / 0.028, 0.55, 1.0))
    nodes = []
    for f, ped in zip(fruits, truss.pedicel_m, strict=True):
        node = f.top_m + ped * _UP
        if truss.layout == "cluster" and len(fruits) > 1:
            node = node + (-0.5 if f.index % 2 == 0 else 0.5) * 0.6 * f.radius_m * truss.side
        nodes.append(node)
    nodes_arr = np.array(nodes)
    # lift the rachis where it would pass through a fruit
    for _ in range(10):
        path = plants.smooth_path(np.vstack([truss.attach, nodes_arr]), 5)
        bad = _inside_fruit(path, fruits, 0.004)
        if not bad.any():
            break
        nodes_arr[:, 2] += 0.004
    out = np.array([-0.012, 0.0, 0.006]) if len(nodes_arr) else np.zeros(3)
    lead = truss.attach + out
    last = nodes_arr[-1] - (nodes_arr[-2] if len(nodes_arr) > 1 else lead)
    tail = nodes_arr[-1] + 0.012 * last / max(float(np.linalg.norm(last)), 1e-9)
    rachis = plants.smooth_path(np.vstack([truss.attach, lead, nodes_arr, tail]), 4)
    radius = 0.0028 * small
    parts.extend(plants.tube(rachis, np.linspace(radius, 0.6 * radius, len(rachis)), 6))
    for f, node in zip(fruits, nodes_arr, strict=True):
        top = f.top_m
        knuckle = top + 0.45 * (node - top) + rng.uniform(-0.002, 0.002, 3)
        pts = np.array(
            [top - 0.002 * _UP, top + 0.25 * (node - top), knuckle, knuckle + 0.08 * (node - top), node]
        )
        rp = 0.0015 * small
        parts.extend(plants.tube(pts, np.array([rp, rp, 1.7 * rp, rp, rp]), 5))
    return parts
