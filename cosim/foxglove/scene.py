"""The render scene as a foxglove.SceneUpdate: one entity per machine and for the auger, stream, grain, ground.

:func:`cosim.world.scene.scene_from_state` builds the scene the renderers draw (world frame: x forward, y left,
z up, m); this module turns it into Foxglove scene entities, so the 3D panel shows the same geometry:

* ``combine``, ``tractor``, ``cart``: their boxes as CubePrimitives (or their mesh as a TriangleListPrimitive)
  and their cylinders (wheels) as CylinderPrimitives, frame ``world``;
* ``ground``: the ground slab; ``auger``: the tube from pivot to spout; ``stream``: the grain stream's segments;
* ``grain``: the grain surface as a TriangleListPrimitive in frame ``cart_grid``, the same triangulated height
  field the renderers draw (:mod:`cosim.world.heightfield`).

The scene's arrays are concatenated in the order :func:`~cosim.world.scene.scene_from_state` appends them (per
machine its boxes then, after the machines, the ground box; per machine its cylinders, then the auger tube,
then the stream), which is how they are split back into entities here.
"""
from __future__ import annotations

import math

import numpy as np
from foxglove.messages import (
    Color,
    CubePrimitive,
    CylinderPrimitive,
    Point3,
    Pose,
    Quaternion,
    SceneEntity,
    SceneUpdate,
    TriangleListPrimitive,
    Vector3,
)

from cosim.world.heightfield import grid_triangles, grid_vertices, padded_heights
from cosim.world.parts import entity_parts
from cosim.world.scene import GRAIN_COLOUR, Scene

from .messages import quaternion_from_matrix, stamp

__all__ = ["scene_update", "ENTITIES", "srgb"]

#: entity ids of a scene update
ENTITIES = ("combine", "tractor", "cart", "ground", "auger", "stream", "grain")


def srgb(linear, alpha: float = 1.0) -> Color:
    """Foxglove Color (sRGB, what the app shows) of a linear RGB triple in [0, 1]."""
    c = [12.92 * v if v <= 0.0031308 else 1.055 * v ** (1 / 2.4) - 0.055 for v in np.clip(linear, 0, 1).tolist()]
    return Color(r=c[0], g=c[1], b=c[2], a=alpha)


def _pose(position, q: tuple[float, float, float, float]) -> Pose:
    x, y, z = (float(v) for v in position)
    return Pose(position=Vector3(x=x, y=y, z=z), orientation=Quaternion(x=q[0], y=q[1], z=q[2], w=q[3]))


def _cubes(scene: Scene, lo: int, hi: int) -> list[CubePrimitive]:
    b = scene.boxes
    return [CubePrimitive(pose=_pose(b.world_from_box[k][:3, 3], quaternion_from_matrix(b.world_from_box[k])),
                          size=Vector3(x=2 * b.half_extents[k][0], y=2 * b.half_extents[k][1], z=2 * b.half_extents[k][2]),
                          color=srgb(b.colour[k])) for k in range(lo, hi)]


def z_to(d: np.ndarray) -> tuple[float, float, float, float]:
    """Quaternion (x, y, z, w) of the shortest rotation taking +z onto unit vector ``d``."""
    cz = float(np.clip(d[2], -1.0, 1.0))
    axis = np.array([-d[1], d[0], 0.0])
    n = float(np.linalg.norm(axis))
    if n < 1e-12:
        return (0.0, 0.0, 0.0, 1.0) if cz > 0 else (1.0, 0.0, 0.0, 0.0)
    half = 0.5 * math.acos(cz)
    s = math.sin(half) / n
    return axis[0] * s, axis[1] * s, 0.0, math.cos(half)


def _cylinders(scene: Scene, lo: int, hi: int) -> list[CylinderPrimitive]:
    c = scene.cylinders
    out = []
    for k in range(lo, hi):
        d = np.asarray(c.p1[k], float) - np.asarray(c.p0[k], float)
        length = float(np.linalg.norm(d))
        if length <= 0.0:
            continue
        r2 = 2.0 * float(c.radius[k])
        out.append(CylinderPrimitive(pose=_pose(0.5 * (np.asarray(c.p0[k]) + c.p1[k]), z_to(d / length)),
                                     size=Vector3(x=r2, y=r2, z=length), bottom_scale=1.0, top_scale=1.0,
                                     color=srgb(c.colour[k])))
    return out


def _triangles(vertices: np.ndarray, faces: np.ndarray, colour, pose: Pose | None = None) -> TriangleListPrimitive:
    pts = [Point3(x=x, y=y, z=z) for x, y, z in np.asarray(vertices, float).tolist()]
    return TriangleListPrimitive(pose=pose, points=pts, color=srgb(colour),
                                 indices=np.asarray(faces, np.int64).ravel().tolist())


def grain_surface(scene: Scene) -> TriangleListPrimitive:
    """The grain surface in the cart grid frame (vertices at the cell centres, padded to the walls)."""
    hf = scene.heightfield
    nx, ny = hf.heights.shape
    xy = grid_vertices(nx, ny, hf.cell_m, hf.length_m, hf.width_m)
    z = np.nan_to_num(padded_heights(hf.heights).ravel(), nan=0.0)

    return _triangles(np.column_stack([xy, z]), grid_triangles(nx, ny), GRAIN_COLOUR)


def scene_update(scenario, scene: Scene, t_ns: int) -> SceneUpdate:
    """SceneUpdate of ``scene`` (built for ``scenario``) at time ``t_ns``: the entities of :data:`ENTITIES`."""
    ts = stamp(t_ns)
    entities, b, c = [], 0, 0
    meshes = {m.name: m for m in scene.meshes}
    for name, p in entity_parts(scenario).items():
        nb = 0 if p.mesh_file is not None else len(p.half_extents)
        nc = len(p.cyl_radius)
        tris = []
        if name in meshes:
            m = meshes[name]
            world = m.vertices @ m.world_from_mesh[:3, :3].T + m.world_from_mesh[:3, 3]
            tris = [_triangles(world, m.faces, m.colour)]
        entities.append(SceneEntity(timestamp=ts, frame_id="world", id=name, cubes=_cubes(scene, b, b + nb),
                                    cylinders=_cylinders(scene, c, c + nc), triangles=tris))
        b, c = b + nb, c + nc
    g = scene.ground_box
    entities.append(SceneEntity(timestamp=ts, frame_id="world", id="ground",
                                cubes=_cubes(scene, g, g + 1) if g is not None else []))
    entities.append(SceneEntity(timestamp=ts, frame_id="world", id="auger", cylinders=_cylinders(scene, c, c + 1)))
    entities.append(SceneEntity(timestamp=ts, frame_id="world", id="stream",
                                cylinders=_cylinders(scene, c + 1, len(scene.cylinders))))
    entities.append(SceneEntity(timestamp=ts, frame_id="cart_grid", id="grain", triangles=[grain_surface(scene)]))
    return SceneUpdate(entities=entities)
