"""The triangles of a mesh that no beam of the LiDAR pattern can meet, left out before the beam-native renderer
draws them (pure numpy, no GL).

The terrain's patch (cosim.world.terrain) is a square of about 40 m around the cart, two triangles per cell, of
which the LiDAR sees a wedge: most triangles lie beside, behind or below its field, and the geometry shader
(``shaders/beam.geom``) bounds each of them only to emit nothing. The beams of a grid or honeycomb pattern lie
inside the four planes through the sensor origin and the pattern's adjacent corner beams (the great circles of
its sides); :func:`pattern_planes` gives each plane's inward normal ``n`` and the least ``n . d`` over the beams
(``floor``, about 0). A triangle whose three corners p all satisfy ``n . p < (floor - CULL_MARGIN) |p|`` for one
plane lies, with its whole convex hull, in a cone that no beam enters (the points p with ``n . p / |p|`` below
``floor - CULL_MARGIN``), :data:`CULL_MARGIN` away, far beyond the fragment test's float32 round-off and its
barycentric slack: the fragment shader discards every beam it is tested against, so leaving it out changes no
pixel. The kept triangles keep their order (the depth test resolves ties by it).
"""
from __future__ import annotations

import numpy as np

__all__ = ["CULL_MARGIN", "pattern_planes", "visible_faces"]

#: how far (in n . p / |p|, about rad) outside the pattern's planes a triangle's corners must all lie to be left out
CULL_MARGIN = 1e-3


def pattern_planes(direction_image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The planes of the pattern's sides: ``direction_image`` (rows, cols, 3) unit beam directions (sensor
    frame) -> (normals (4, 3) float64, floor (4,) float64): the planes through the origin and the corner beams
    (0, 0), (0, -1), (-1, -1), (-1, 0) taken in turn, each normal turned towards the beams' mean, and the least
    ``normal . d`` over every beam d (a side plane the beams straddle, as in a pattern wider than 180 degrees,
    has a floor near -1 and never culls)."""
    img = np.asarray(direction_image, np.float64)
    d = img.reshape(-1, 3)
    d = d / np.linalg.norm(d, axis=1)[:, None]
    corners = [img[0, 0], img[0, -1], img[-1, -1], img[-1, 0]]
    normals = []
    for a, b in zip(corners, corners[1:] + corners[:1]):
        n = np.cross(a, b)
        size = float(np.linalg.norm(n))
        n = n / size if size > 0.0 else np.zeros(3)
        normals.append(n if float((d @ n).sum()) >= 0.0 else -n)
    normals = np.array(normals)
    floor = (d @ normals.T).min(axis=0) if len(d) else np.full(4, -1.0)
    return normals, np.where(np.linalg.norm(normals, axis=1) > 0.0, floor, -np.inf)


def visible_faces(points: np.ndarray, faces: np.ndarray, normals: np.ndarray, floor: np.ndarray) -> np.ndarray:
    """The rows of ``faces`` (F, 3) int whose triangle a beam may meet, in their order: ``points`` (V, 3) m the
    mesh's vertices in the sensor frame relative to its origin, ``normals``, ``floor`` from :func:`pattern_planes`
    (at most 8 planes).
    A triangle is left out when its three corners lie outside one plane by :data:`CULL_MARGIN` (module
    docstring)."""
    p = np.asarray(points, np.float64)
    size = np.sqrt(np.einsum("vj,vj->v", p, p))
    outside = p @ normals.T < (floor - CULL_MARGIN)[None, :] * size[:, None]                      # (V, planes)
    bits = outside.view(np.uint8) @ (1 << np.arange(outside.shape[1], dtype=np.uint8))        # (V,) plane bits
    corner = np.take(bits, faces)                                                                # (F, 3)
    gone = (corner[:, 0] & corner[:, 1] & corner[:, 2]) != 0                     # all three outside one plane
    return np.compress(~gone, faces, axis=0)
