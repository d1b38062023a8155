"""Exact ray cast with the label of what each ray meets first (docs/cameras.md): the reference for the camera
label images, and the mock renderer's labels.

The scene's primitives are grouped by label (``Boxes.label``, ``Cylinders.label``, the grain surface is
``GRAIN``, a mesh its entity's label or, the terrain's patch, the ground) and each group is cast with the numpy ray caster's exact intersectors
(``cosim.world.raycast``), the best hit so far bounding the next group's search: the nearest hit wins and
carries its group's label. The distances are those of :func:`cosim.world.raycast.raycast` (the same
intersectors, the same minimum), so depth and label always agree.
"""
from __future__ import annotations

import numpy as np

from .labels import GRAIN, NONE, mesh_label
from .raycast import ray_boxes, ray_cylinders, ray_heightfield, ray_mesh
from .scene import Boxes, Cylinders, Scene

__all__ = ["cast_labels"]


def _take_boxes(b: Boxes, keep: np.ndarray) -> Boxes:
    return Boxes(b.world_from_box[keep], b.half_extents[keep], b.colour[keep])


def _take_cylinders(c: Cylinders, keep: np.ndarray) -> Cylinders:
    return Cylinders(c.p0[keep], c.p1[keep], c.radius[keep], c.colour[keep])


def cast_labels(scene: Scene, origin: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rays from ``origin`` (3,) m along unit ``directions`` (N, 3), world frame -> (t (N,) float64 m, inf on a
    miss; label (N,) uint8, ``NONE`` on a miss). Unlabelled boxes and cylinders (label None) count as ``NONE``."""
    d = np.ascontiguousarray(directions, dtype=np.float64).reshape(-1, 3)
    o = np.broadcast_to(np.asarray(origin, np.float64).reshape(3), d.shape)
    best = ray_heightfield(o, d, scene.heightfield)
    label = np.where(np.isfinite(best), GRAIN, NONE).astype(np.uint8)

    def merge(t: np.ndarray, code: int) -> None:
        nearer = t < best
        best[nearer] = t[nearer]
        label[nearer] = code

    cyl = scene.cylinders
    codes = cyl.label if cyl.label is not None else np.full(len(cyl), NONE, np.uint8)
    for code in np.unique(codes):
        merge(ray_cylinders(o, d, _take_cylinders(cyl, codes == code), t_max=best), int(code))
    boxes = scene.boxes
    codes = boxes.label if boxes.label is not None else np.full(len(boxes), NONE, np.uint8)
    for code in np.unique(codes):
        merge(ray_boxes(o, d, _take_boxes(boxes, codes == code), t_max=best), int(code))
    for mesh in scene.meshes:
        merge(ray_mesh(o, d, mesh), mesh_label(mesh.name))
    return best, label
