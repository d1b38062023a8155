"""A :class:`~cosim.world.scene.Scene` as one triangle list: the surfaces the ray caster intersects, exactly.

Every primitive of the scene is already a polyhedron or a triangulated surface, so this is exact, not an
approximation:

* boxes: the unit cube's 12 triangles (``cosim.world.meshes.unit_cube``) scaled by the half extents and
  placed by ``world_from_box`` (the ground slab included: its top face is the ground plane);
* cylinders: the capped ``CYLINDER_SIDES``-facet prisms the GL renderer draws and ``cosim.world.raycast``
  clips (``unit_cylinder`` in the frame of ``orthonormal_frames``);
* the grain surface: the vertex grid and quad split of ``cosim.world.heightfield`` (``grid_vertices``,
  ``padded_heights``, ``grid_triangles``), placed by ``world_from_grid``;
* meshes: their own triangles, placed by ``world_from_mesh``.

One difference from ``cosim.world.raycast``: the numpy caster treats the grain as the solid under its
surface (a ray entering the grain's bounding slab through a side below the surface hits that side); here,
as in the GL renderer, the surface alone is drawn. The cart walls hide those sides from a sensor outside
the cart, so the two agree there.

Vertices are returned relative to an ``origin`` (the LiDAR or camera position), computed in float64: a
float32 consumer then keeps micrometres near the sensor whatever the world coordinates.
"""
from __future__ import annotations

import functools

import numpy as np

from .heightfield import grid_triangles, grid_vertices, padded_heights
from .labels import GRAIN, NONE, mesh_label
from .meshes import CYLINDER_SIDES, orthonormal_frames, unit_cube, unit_cylinder
from .scene import Scene

__all__ = ["face_labels", "scene_triangles"]


@functools.lru_cache(maxsize=1)
def _unit_meshes() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(cube vertices (8, 3), cube faces (12, 3), cylinder vertices (2 n + 2, 3), cylinder faces (4 n, 3)),
    float64 / int64."""
    cv, cf = unit_cube()
    yv, yf = unit_cylinder(CYLINDER_SIDES, np.float64)
    return cv.astype(np.float64), cf.astype(np.int64), yv.astype(np.float64), yf.astype(np.int64)


def _instances(unit_v: np.ndarray, unit_f: np.ndarray, lin: np.ndarray, trans: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
    """K copies of a unit mesh, vertex p -> lin_k p + trans_k: ``lin`` (K, 3, 3), ``trans`` (K, 3) ->
    (vertices (K V, 3), faces (K F, 3) into them)."""
    v = np.einsum("kij,vj->kvi", lin, unit_v) + trans[:, None, :]
    f = unit_f[None] + (np.arange(len(lin)) * len(unit_v))[:, None, None]
    return v.reshape(-1, 3), f.reshape(-1, 3)


def scene_triangles(scene: Scene, origin: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every surface of ``scene`` as triangles: (vertices (V, 3) float64 m, world axes, relative to
    ``origin`` (3,) m; faces (F, 3) int64 into them). Order: boxes, cylinders, grain surface, meshes."""
    origin = np.asarray(origin, np.float64)
    cv, cf, yv, yf = _unit_meshes()
    parts = []
    b = scene.boxes
    if len(b):
        parts.append(_instances(cv, cf, b.world_from_box[:, :3, :3] * b.half_extents[:, None, :],
                                b.world_from_box[:, :3, 3] - origin))
    c = scene.cylinders
    if len(c):
        axis = c.p1 - c.p0
        scale = np.stack([c.radius, c.radius, np.linalg.norm(axis, axis=1)], axis=1)
        parts.append(_instances(yv, yf, orthonormal_frames(axis) * scale[:, None, :], c.p0 - origin))
    hf = scene.heightfield
    nx, ny = hf.heights.shape
    xy = grid_vertices(nx, ny, hf.cell_m, hf.length_m, hf.width_m, np.float64)
    grid = np.column_stack([xy, padded_heights(np.asarray(hf.heights, np.float64)).ravel()])
    m = hf.world_from_grid
    parts.append((grid @ m[:3, :3].T + (m[:3, 3] - origin), grid_triangles(nx, ny).astype(np.int64)))
    for mesh in scene.meshes:
        m = mesh.world_from_mesh
        parts.append((np.asarray(mesh.vertices, np.float64) @ m[:3, :3].T + (m[:3, 3] - origin),
                      np.asarray(mesh.faces, np.int64)))
    verts, faces, base = [], [], 0
    for v, f in parts:
        verts.append(v)
        faces.append(f + base)
        base += len(v)
    return np.concatenate(verts), np.concatenate(faces)


def face_labels(scene: Scene) -> np.ndarray:
    """(F,) uint8: the label (``cosim.world.labels``) of each face of :func:`scene_triangles` ``(scene, ...)``, in
    its order: a box's or a cylinder's own (``NONE`` where the scene's boxes or cylinders carry none), ``GRAIN`` on
    the grain surface, a mesh its entity's (:func:`~cosim.world.labels.mesh_label`)."""
    _, cf, _, yf = _unit_meshes()
    b, c, hf = scene.boxes, scene.cylinders, scene.heightfield
    box = b.label if b.label is not None else np.full(len(b), NONE, np.uint8)
    cyl = c.label if c.label is not None else np.full(len(c), NONE, np.uint8)
    nx, ny = hf.heights.shape
    parts = [np.repeat(np.asarray(box, np.uint8), len(cf)), np.repeat(np.asarray(cyl, np.uint8), len(yf)),
             np.full(len(grid_triangles(nx, ny)), GRAIN, np.uint8)]
    parts += [np.full(len(m.faces), mesh_label(m.name), np.uint8) for m in scene.meshes]
    return np.concatenate(parts)
