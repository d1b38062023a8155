"""Triangle meshes and per-instance records for the GL renderer (pure numpy, no GL).

Boxes and cylinders are drawn instanced from one unit mesh each: the unit cube [-1, 1]^3 scaled by the half
extents, and a unit cylinder (radius 1, z from 0 to 1, ``CYLINDER_SIDES`` facets, capped) scaled by
(r, r, length). An instance record is 19 float32: the 4 x 4 world_from_unit matrix in column-major order
(as a GLSL ``mat4`` attribute reads it) followed by the linear RGB colour.
"""
from __future__ import annotations

import numpy as np

from .scene import Boxes, Cylinders

__all__ = [
    "CYLINDER_SIDES",
    "INSTANCE_FLOATS",
    "box_instances",
    "cylinder_instances",
    "orthonormal_frames",
    "pack_instances",
    "unit_cube",
    "unit_cylinder",
]

#: facets of a drawn cylinder (an inscribed prism): the radial deviation from the exact cylinder is
#: r (1 - cos(pi / n)), 2.9 mm for the 0.15 m grain stream at n = 16
CYLINDER_SIDES = 16
#: floats per instance record (mat4 + rgb)
INSTANCE_FLOATS = 19


def unit_cube(open_top: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Cube [-1, 1]^3: vertices (8, 3) float32, triangles (12, 3) int32 (10 without the +z face when
    ``open_top``), wound counter-clockwise seen from outside."""
    v = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=np.float32)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    if open_top:
        quads = quads[:-1]                 # (1, 5, 7, 3): the four z = +1 vertices
    tri = [(a, b, c) for a, b, c, d in quads] + [(a, c, d) for a, b, c, d in quads]
    return v, np.array(tri, dtype=np.int32)


def unit_cylinder(sides: int = CYLINDER_SIDES, dtype=np.float32) -> tuple[np.ndarray, np.ndarray]:
    """Capped cylinder of radius 1 (inscribed prism: vertices on the circle) along z in [0, 1]:
    vertices (2 sides + 2, 3) of ``dtype`` (float32 for GL), triangles (4 sides, 3) int32."""
    a = 2.0 * np.pi * np.arange(sides) / sides
    ring = np.stack([np.cos(a), np.sin(a)], axis=1)
    v = np.concatenate([np.c_[ring, np.zeros(sides)], np.c_[ring, np.ones(sides)], [[0, 0, 0], [0, 0, 1]]])
    k, k1 = np.arange(sides), (np.arange(sides) + 1) % sides
    side = np.concatenate([np.stack([k, k1, k1 + sides], 1), np.stack([k, k1 + sides, k + sides], 1)])
    caps = np.concatenate([np.stack([np.full(sides, 2 * sides), k1, k], 1),
                           np.stack([np.full(sides, 2 * sides + 1), k + sides, k1 + sides], 1)])
    return v.astype(dtype), np.concatenate([side, caps]).astype(np.int32)


def pack_instances(world_from_unit: np.ndarray, colour: np.ndarray, origin=None) -> np.ndarray:
    """(N, 4, 4) matrices and (N, 3) colours -> (N, 19) float32 records (matrix column-major).

    ``origin`` (3,) m, optional: subtracted from the translations in float64 before the cast to float32, so
    the GPU works in coordinates near the scene (float32 keeps ~1 um at 10 m, only ~15 um at 200 m)."""
    world_from_unit = np.array(world_from_unit, dtype=np.float64)
    if origin is not None:
        world_from_unit[:, :3, 3] -= np.asarray(origin, dtype=np.float64)
    m = np.transpose(world_from_unit, (0, 2, 1)).reshape(-1, 16)
    return np.concatenate([m, np.asarray(colour).reshape(-1, 3)], axis=1).astype(np.float32)


def box_instances(boxes: Boxes, origin=None) -> np.ndarray:
    """(N, 19) float32 instance records of the unit cube for ``boxes`` (relative to ``origin``, m), in order."""
    scale = np.zeros((len(boxes), 4, 4))
    scale[:, [0, 1, 2], [0, 1, 2]] = boxes.half_extents
    scale[:, 3, 3] = 1.0
    return pack_instances(boxes.world_from_box @ scale, boxes.colour, origin)


def orthonormal_frames(axis: np.ndarray) -> np.ndarray:
    """(M, 3, 3) rotations whose third column is the unit ``axis`` (M, 3)."""
    z = axis / np.linalg.norm(axis, axis=1, keepdims=True)
    # x = unit(helper x z) with helper = e_x where |z_x| < 0.9, else e_y; written out (np.cross costs more
    # in overhead than the arithmetic for a few dozen rows)
    zx, zy, zz = z[:, 0], z[:, 1], z[:, 2]
    use_ex = np.abs(zx) < 0.9
    zero = np.zeros_like(zx)
    x = np.where(use_ex[:, None], np.stack([zero, -zz, zy], axis=1), np.stack([zz, zero, -zx], axis=1))
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    y = np.stack([zy * x[:, 2] - zz * x[:, 1], zz * x[:, 0] - zx * x[:, 2], zx * x[:, 1] - zy * x[:, 0]], axis=1)
    return np.stack([x, y, z], axis=2)


def cylinder_instances(cyl: Cylinders, origin=None) -> np.ndarray:
    """(M, 19) float32 instance records of the unit cylinder for ``cyl`` (relative to ``origin``, m)."""
    m = len(cyl)
    if m == 0:
        return np.zeros((0, INSTANCE_FLOATS), np.float32)
    axis = cyl.p1 - cyl.p0
    t = np.zeros((m, 4, 4))
    t[:, :3, :3] = orthonormal_frames(axis) * np.stack(
        [cyl.radius, cyl.radius, np.linalg.norm(axis, axis=1)], axis=1)[:, None, :]
    t[:, :3, 3] = cyl.p0
    t[:, 3, 3] = 1.0
    return pack_instances(t, cyl.colour, origin)
