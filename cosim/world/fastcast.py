"""The fast exact ray cast from one origin (a LiDAR, a camera): Intel Embree when installed, else the numpy
reference ``cosim.world.raycast``.

Embree (the ``embreex`` binding; an exact reference like the numpy ray cast) traverses a BVH
of the scene's triangles (``cosim.world.triangles``: the same surfaces the numpy caster intersects in closed
form) in float32, built per frame. It decides which triangle each ray hits first; the range is then
recomputed in float64 as the intersection of the ray with that triangle's plane, so it is exact like the
numpy caster's, not float32. Only coverage is decided in float32: a ray passing within about a micrometre
of a silhouette edge can be called the other way than float64 would (the triangles are built around the
origin, so float32 keeps ~1 um at 10 m). Agreement with the numpy caster is tested beam for beam on real
frames (``tests/test_fastcast.py``).

Rays: ``origin`` (3,) m and ``directions`` (N, 3) unit, world frame; the result (N,) float64 m is the
distance to the first hit, ``inf`` on a miss, as :func:`cosim.world.raycast.raycast`.
"""
from __future__ import annotations

import importlib.util
from collections.abc import Mapping
from typing import TYPE_CHECKING, Literal

import numpy as np

from .labelcast import cast_labels
from .labels import NONE
from .raycast import T_MIN_M, raycast
from .scene import Scene
from .triangles import face_labels, scene_triangles

if TYPE_CHECKING:
    from .parts import EntityParts

__all__ = ["BACKENDS", "CASTERS", "Backend", "Caster", "cast_from", "embree_available", "embree_cast",
           "embree_cast_labels", "make_caster"]

Backend = Literal["auto", "embree", "numpy"]
#: the accepted backend names: auto is Embree when it is installed, else numpy
BACKENDS = ("auto", "embree", "numpy")
#: Embree's miss marker is tfar left at its initial value (1e37); anything beyond this is a miss, m
_MISS_M = 1e30
#: the float64 re-intersection is used unless the ray grazes the plane (|n . d| below this times |n|)
_GRAZE = 1e-9
#: the ray casters a run can use, by name (their index is the code a renderer records): ``numpy``
#: (``cosim.world.raycast``), ``embree`` (the scene's triangles built every frame, :func:`embree_cast`),
#: ``embree-static`` (the rigid bodies built once per run, ``cosim.world.rigidcast``)
CASTERS = ("none", "numpy", "embree", "embree-static")


def embree_available() -> bool:
    """Whether the ``embreex`` package can be imported (the ``fast`` extra)."""
    return importlib.util.find_spec("embreex") is not None


def _embree_first_hits(scene: Scene, origin: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rays from ``origin`` (3,) along ``directions`` (N, 3) through ``scene``'s triangles (one BVH built for the
    call): (t (N,) float64 m, inf on a miss; the face of :func:`~cosim.world.triangles.scene_triangles` each ray
    hits first (N,) int64, -1 on a miss). Raises ImportError when embreex is not installed."""
    from embreex import rtcore_scene
    from embreex.mesh_construction import TriangleMesh

    origin = np.asarray(origin, np.float64).reshape(3)
    d = np.ascontiguousarray(directions, dtype=np.float64).reshape(-1, 3)
    verts, faces = scene_triangles(scene, origin)
    emb = rtcore_scene.EmbreeScene()
    TriangleMesh(emb, verts.astype(np.float32), faces.astype(np.int32))
    out = emb.run(np.zeros(d.shape, np.float32), d.astype(np.float32), output=True)
    prim = out["primID"]
    t = np.full(len(d), np.inf)
    face = np.full(len(d), -1, np.int64)
    hit = np.flatnonzero((prim >= 0) & (out["tfar"] < _MISS_M))
    if hit.size == 0:
        return t, face
    # exact range: the ray against the hit triangle's plane in float64 (origin at 0: t = n . v0 / n . d), the
    # planes computed once per triangle
    tri = verts[faces]                                                    # (F, 3, 3)
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    offsets = np.einsum("fi,fi->f", normals, tri[:, 0])
    n = normals[prim[hit]]
    nd = np.einsum("hi,hi->h", n, d[hit])
    ok = np.abs(nd) > _GRAZE * np.linalg.norm(n, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        t64 = offsets[prim[hit]] / nd
    t_hit = np.where(ok, t64, out["tfar"][hit].astype(np.float64))
    t[hit] = np.where(t_hit > T_MIN_M, t_hit, np.inf)
    face[hit] = np.where(t_hit > T_MIN_M, prim[hit], -1)
    return t, face


def embree_cast(scene: Scene, origin: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Rays from ``origin`` (3,) along ``directions`` (N, 3) through ``scene`` with Embree: (N,) float64 m,
    inf on a miss (first hit with t > ``T_MIN_M``; hits behind are never reported by Embree's tnear = 0).
    Raises ImportError when embreex is not installed."""
    return _embree_first_hits(scene, origin, directions)[0]


def embree_cast_labels(scene: Scene, origin: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`embree_cast` with the label of what each ray meets first: (t (N,) float64 m, inf on a miss; label
    (N,) uint8, ``NONE`` on a miss), as :func:`cosim.world.labelcast.cast_labels` gives them (the grain is its
    surface here, not the solid under it: the cart's walls hide the difference from outside the cart)."""
    t, face = _embree_first_hits(scene, origin, directions)
    label = np.full(len(t), NONE, np.uint8)
    hit = face >= 0
    label[hit] = face_labels(scene)[face[hit]]
    return t, label


def cast_from(scene: Scene, origin: np.ndarray, directions: np.ndarray, backend: Backend = "auto") -> np.ndarray:
    """Exact ranges (N,) float64 m (inf on a miss) of rays from ``origin`` (3,) along unit ``directions``
    (N, 3), world frame. ``backend``: ``embree`` (raises ImportError without embreex), ``numpy`` (the
    readable reference) or ``auto`` (Embree when installed)."""
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")
    if backend == "embree" or (backend == "auto" and embree_available()):
        return embree_cast(scene, origin, directions)
    d = np.asarray(directions, np.float64).reshape(-1, 3)
    return raycast(scene, np.broadcast_to(np.asarray(origin, np.float64).reshape(3), d.shape), d)


class Caster:
    """A run's exact ray cast: ``cast(scene, origin, directions)`` as :func:`cast_from`; ``name`` (one of
    :data:`CASTERS`) says which ray caster runs. Made by :func:`make_caster`; :meth:`close` when done."""

    def __init__(self, backend: Backend, static=None):
        self._backend, self._static = backend, static
        if static is not None:
            self.name = "embree-static"
        else:
            self.name = "embree" if backend == "embree" or (backend == "auto" and embree_available()) else "numpy"

    def cast(self, scene: Scene, origin: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """Exact ranges (N,) float64 m, inf on a miss (see :func:`cast_from`); a scene without entity poses
        (not from ``scene_from_state``) goes through :func:`cast_from`."""
        if self._static is not None and scene.poses is not None:
            return self._static.cast(scene, origin, directions)
        return cast_from(scene, origin, directions, "embree" if self._static is not None else self._backend)

    def cast_labels(self, scene: Scene, origin: np.ndarray, directions: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
        """Exact ranges (N,) float64 m (inf on a miss) and the label (N,) uint8 of what each ray meets first
        (``NONE`` on a miss): :func:`embree_cast_labels` where Embree runs (the scene's triangles built for the
        call: the rigid bodies built once carry no labels), else the numpy label cast
        (:func:`cosim.world.labelcast.cast_labels`). ``label_name`` says which."""
        if self.label_name == "embree":
            return embree_cast_labels(scene, origin, directions)
        return cast_labels(scene, origin, directions)

    @property
    def label_name(self) -> str:
        """The ray caster of :meth:`cast_labels`: ``embree`` or ``numpy``."""
        return "numpy" if self.name == "numpy" else "embree"

    def close(self) -> None:
        if self._static is not None:
            self._static.close()
            self._static = None


def make_caster(parts: Mapping[str, "EntityParts"] | None = None, backend: Backend = "auto") -> Caster:
    """The fastest exact ray cast available for a run of scenes with these entity ``parts``
    (``cosim.world.parts.entity_parts``): the rigid bodies built once (``cosim.world.rigidcast``) where
    Embree's library can be used so, else :func:`cast_from` with ``backend``. ``parts`` None: :func:`cast_from`."""
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")
    if parts is not None and (backend == "embree" or (backend == "auto" and embree_available())):
        from .embree_api import EmbreeUnavailable
        from .rigidcast import RigidCaster

        try:
            return Caster(backend, RigidCaster(parts))
        except EmbreeUnavailable:
            pass
    return Caster(backend)
