"""The exact ray cast with static geometry built once per run: each rigid body's parts in its own frame.

:func:`cosim.world.fastcast.embree_cast` turns the whole scene into triangles and builds Embree's BVH every
frame; most of that scene never changes shape. :class:`RigidCaster` builds, once per run, one Embree scene per
entity (combine, tractor, cart: their boxes, wheels and mesh files, ``cosim.world.parts``) in its body frame,
and per frame only places it (an instance transform: the rays are moved into the body's frame by Embree). The
rest moves or changes shape every frame and is kept as cheap to update as it can be:

* the grain surface is a height field on a fixed grid (``cosim.world.heightfield``): its vertex heights are
  written into the shared vertex buffer and the BVH is refitted, placed by ``world_from_grid``;
* the other boxes (the ground slab) and cylinders (the auger tube, the grain stream) are instances of the unit
  cube and the unit prism, each scaled and placed per frame (a pool of instances that grows as needed);
* a mesh that is no entity's (the terrain's patch on uneven ground, cosim.world.terrain) is a refittable
  prototype whose vertices are rewritten when the patch moves on (its name changes), placed per frame.

An instance that encloses no volume (a prism of zero radius or length, a box of zero extent: :func:`has_volume`)
is hidden for the frame, never given to Embree nor inverted: it has no surface a ray can meet except on a set of
measure zero, and GL draws no fragment of it.

Embree decides which triangle each ray hits first (float32, in the instance's frame); the range is then the
float64 intersection of the ray with that triangle's plane, placed in the world, as in ``embree_cast``, so the
two agree to rounding (tested beam for beam, ``tests/test_rigidcast.py``). Rays: ``origin`` (3,) and unit
``directions`` (N, 3), world frame, m; result (N,) float64 m, inf on a miss. Needs the scene's ``poses``
(:func:`cosim.world.scene.scene_from_state` records them) and Embree (:mod:`cosim.world.embree_api`).
"""
from __future__ import annotations

import weakref
from collections.abc import Mapping

import numpy as np

from . import embree_api as emb
from .heightfield import grid_triangles, grid_vertices, padded_heights
from .meshes import CYLINDER_SIDES, orthonormal_frames, unit_cube, unit_cylinder
from .parts import EntityParts
from .raycast import T_MIN_M
from .scene import MIN_SEGMENT_M, Scene, load_mesh

__all__ = ["RigidCaster", "body_triangles", "has_volume"]

#: Embree's miss marker is tfar left at its initial value (1e37); anything beyond this is a miss, m
_MISS_M = 1e30
#: the float64 re-intersection is used unless the ray grazes the plane (|n . d| below this times |n|)
_GRAZE = 1e-9
#: Embree's tfar for a ray that hits nothing (its own default), m
_NO_HIT = 1e37
#: relative (and absolute, m) slack on the ground's range given to Embree as tfar: float32 rounding never hides
#: a hit just before the ground (the float64 comparison after the traversal decides)
_TFAR_SLACK = 1e-6
_EYE3 = np.eye(3)
#: an instance whose linear map has an axis shorter than this (a prism of zero radius or length, a box of zero
#: extent) encloses no volume and is not cast, m (the scene's own threshold for stream segments)
_MIN_SCALE_M = MIN_SEGMENT_M
#: ... nor one whose axes are nearly coplanar: |det| below this share of the product of the axes' lengths
_MIN_SHAPE = 1e-9


def top_face_from_above(world_from_box: np.ndarray, half: np.ndarray, o: np.ndarray, d: np.ndarray
                        ) -> np.ndarray | None:
    """Ranges (N,) m to a box's top face (+z, box frame) of rays from ``o`` (3,) along ``d`` (N, 3) (world), or
    None unless ``o`` lies above that face and within its x, y extent: then a ray meets the box, if at all,
    first through that face (the box's slab test there reduces to the face's plane), inf where it does not.
    The ground slab seen from a sensor above it."""
    rot = world_from_box[:3, :3]
    ob = rot.T @ (o - world_from_box[:3, 3])
    if not (ob[2] > half[2] and abs(ob[0]) < half[0] and abs(ob[1]) < half[1]):
        return None
    db = d if np.array_equal(rot, _EYE3) else d @ rot       # a level slab: the product is d, exactly
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (half[2] - ob[2]) / db[:, 2]
    inside = (db[:, 2] < 0.0) & (np.abs(ob[0] + t * db[:, 0]) <= half[0]) & (np.abs(ob[1] + t * db[:, 1]) <= half[1])
    return np.where(inside, t, np.inf)


def has_volume(lin: np.ndarray, trans: np.ndarray) -> np.ndarray:
    """Which instances (K,) bool enclose a volume Embree can be given: ``lin`` (K, 3, 3) and ``trans`` (K, 3)
    finite, each axis (column) at least ``_MIN_SCALE_M`` long and the axes not nearly coplanar. The others (a
    stream segment of zero radius, a prism of zero length) are flat or empty: Embree would invert their
    transforms into infinities, and they have no plane to intersect in float64."""
    finite = np.isfinite(lin).all(axis=(1, 2)) & np.isfinite(trans).all(axis=1)
    safe = np.where(finite[:, None, None], lin, 0.0)
    axes = np.linalg.norm(safe, axis=1)                                 # (K, 3) the columns' lengths
    det = np.abs(np.linalg.det(safe))
    return finite & (axes.min(axis=1) >= _MIN_SCALE_M) & (det > _MIN_SHAPE * axes.prod(axis=1))


def body_triangles(parts: EntityParts, cylinders: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """One entity's surfaces in its body frame, as ``scene_from_state`` places them: its mesh file (or its
    boxes) then (``cylinders``) its cylinders as prisms. (vertices (V, 3) float64 m, faces (F, 3) int64)."""
    cv, cf = unit_cube()
    yv, yf = unit_cylinder(CYLINDER_SIDES, np.float64)
    pieces = []
    if parts.mesh_file is not None:
        pieces.append(load_mesh(parts.mesh_file))
    else:
        for m, h in zip(parts.body_from_box, parts.half_extents):
            pieces.append((cv.astype(np.float64) * h @ m[:3, :3].T + m[:3, 3], cf))
    axis = parts.cyl_p1 - parts.cyl_p0
    if len(axis) and cylinders:
        lin = orthonormal_frames(axis) * np.stack([parts.cyl_radius, parts.cyl_radius,
                                                    np.linalg.norm(axis, axis=1)], axis=1)[:, None, :]
        for a, p0 in zip(lin, parts.cyl_p0):
            pieces.append((yv @ a.T + p0, yf))
    verts, faces, base = [], [], 0
    for v, f in pieces:
        verts.append(np.asarray(v, np.float64))
        faces.append(np.asarray(f, np.int64) + base)
        base += len(v)
    return np.concatenate(verts), np.concatenate(faces)


def _grid_planes(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    """:func:`_planes` written out per coordinate (the grain surface's every frame: no (F, 3, 3) gather)."""
    a, b, c = (np.take(v, f[:, k], axis=0) for k in range(3))
    e1, e2 = b - a, c - a
    out = np.empty((len(f), 4))
    out[:, 0] = e1[:, 1] * e2[:, 2] - e1[:, 2] * e2[:, 1]
    out[:, 1] = e1[:, 2] * e2[:, 0] - e1[:, 0] * e2[:, 2]
    out[:, 2] = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    out[:, 3] = out[:, 0] * a[:, 0] + out[:, 1] * a[:, 1] + out[:, 2] * a[:, 2]
    return out


def _grid_terms(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    """The terms of :func:`_grid_planes` that depend on x and y alone, which a grid keeps while its heights change:
    (F, 7) float64 per face: the edges from the first vertex e1 = v1 - v0 (x, y), e2 = v2 - v0 (x, y), the first
    vertex's x, y, and the normal's z = e1 x e2 along z."""
    a, b, c = (np.take(v, f[:, k], axis=0) for k in range(3))
    e1, e2 = b - a, c - a
    return np.stack([e1[:, 0], e1[:, 1], e2[:, 0], e2[:, 1], a[:, 0], a[:, 1],
                     e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]], axis=1)


def _grid_planes_at(terms: np.ndarray, z: np.ndarray, f: np.ndarray) -> np.ndarray:
    """:func:`_grid_planes` of faces ``f`` (U, 3) from their :func:`_grid_terms` (U, 7) and the vertex heights
    ``z`` (V,): the same operations on the same operands, so the same bits."""
    az, bz, cz = (np.take(z, f[:, k]) for k in range(3))
    e1z, e2z = bz - az, cz - az
    out = np.empty((len(f), 4))
    out[:, 0] = terms[:, 1] * e2z - e1z * terms[:, 3]
    out[:, 1] = e1z * terms[:, 2] - terms[:, 0] * e2z
    out[:, 2] = terms[:, 6]
    out[:, 3] = out[:, 0] * terms[:, 4] + out[:, 1] * terms[:, 5] + out[:, 2] * az
    return out


def _planes(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Each triangle's plane n . x = c: (F, 4) float64 [n, c], n = (v1 - v0) x (v2 - v0) (not unit)."""
    tri = v[f]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    return np.concatenate([n, np.einsum("fi,fi->f", n, tri[:, 0])[:, None]], axis=1)


def _distinct(rows: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray]:
    """The distinct values of ``rows`` (H,) int in [0, ``size``), ascending (U,), and each row's index among them
    (H,): ``np.unique(rows, return_inverse=True)`` by a mark table of ``size`` entries, without sorting."""
    mark = np.zeros(size, bool)
    mark[rows] = True
    used = np.flatnonzero(mark)
    index = np.empty(size, np.intp)
    index[used] = np.arange(len(used))
    return used, np.take(index, rows)


def _release(holder: list, protos: list) -> None:
    """Drop the embreex top scene and device (``holder``: the last references; the top scene releases its
    instances), then release every prototype scene, then let their buffers go."""
    holder.clear()
    for proto in protos:
        proto.release()
    protos.clear()


class _Proto:
    """A prototype scene holding one geometry (its id ``k``: the prototype's index), instanced once in the top
    scene; ``planes`` (F, 4) of its triangles in its own frame."""

    def __init__(self, device: int, top: int, geom_id: int, v: np.ndarray, f: np.ndarray, quality: int):
        self.k = geom_id
        self.geom = emb.triangles(device, v, f, quality)
        self.scene = emb.prototype_scene(device, self.geom, geom_id)
        emb.api().rtcReleaseGeometry(self.geom.handle)      # the prototype scene holds it
        self.inst = emb.instance(device, top, self.scene, geom_id)
        self.planes = _planes(v, f)
        self.enabled = True

    def place(self, lin: np.ndarray, trans: np.ndarray) -> None:
        """Instance at x_top = lin @ x + trans (lin (3, 3), trans (3,), float64, origin-relative)."""
        emb.set_transform(self.inst, np.concatenate([lin, trans[:, None]], axis=1))
        if not self.enabled:
            emb.api().rtcEnableGeometry(self.inst.handle)
            emb.api().rtcCommitGeometry(self.inst.handle)
            self.enabled = True

    def place_packed(self, m: np.ndarray) -> None:
        """:meth:`place` with the transform already packed: (4, 3) float32, Embree's column-major 3 x 4."""
        emb.set_packed_transform(self.inst, m)
        if not self.enabled:
            emb.api().rtcEnableGeometry(self.inst.handle)
            emb.api().rtcCommitGeometry(self.inst.handle)
            self.enabled = True

    def hide(self) -> None:
        if self.enabled:
            emb.api().rtcDisableGeometry(self.inst.handle)
            emb.api().rtcCommitGeometry(self.inst.handle)
            self.enabled = False

    def release(self) -> None:
        emb.api().rtcReleaseScene(self.scene)


class RigidCaster:
    """Exact ray casts of ``scene_from_state`` scenes of one scenario (``parts``: ``entity_parts(scenario)``),
    the entities' geometry built once. Raises :class:`~cosim.world.embree_api.EmbreeUnavailable` (or
    ImportError without embreex) when Embree cannot be used so; call :meth:`close` when done."""

    def __init__(self, parts: Mapping[str, EntityParts]):
        from embreex import rtcore, rtcore_scene

        self._device_obj = rtcore.EmbreeDevice()
        self._top_obj = rtcore_scene.EmbreeScene(self._device_obj)
        self._top, self._dev = emb.handles(self._top_obj, self._device_obj)
        self._protos: list[_Proto] = []
        # everything released in order (the instances with the top scene, then the prototypes, then the buffers
        # they share) by close(), or when this caster is collected or the interpreter exits without it
        self._holder = [self._top_obj, self._device_obj]
        self._finalizer = weakref.finalize(self, _release, self._holder, self._protos)
        self._bodies: dict[str, _Proto] = {}
        self._n_boxes = self._n_cyl = 0
        cv, cf = unit_cube()
        self._unit = {"cube": (cv.astype(np.float64), cf), "prism": unit_cylinder(CYLINDER_SIDES, np.float64)}
        self._hf: _Proto | None = None                      # made on first use
        self._hf_key: tuple | None = None
        #: scene meshes that are not an entity's (the terrain's patch): (vertices, faces) count -> [proto, name]
        self._extra: dict[tuple[int, int], list] = {}
        #: a tilted body (on uneven ground) is drawn as its boxes alone and its cylinders as dynamic prisms: the
        #: scene's prisms take their facets' phase from the world axis (cosim.world.meshes.orthonormal_frames),
        #: which a body-frame prism turned by roll or pitch does not keep; name -> (boxes-only proto or None,
        #: the body's rows of the scene's cylinders)
        self._parts = dict(parts)
        self._tilted: dict[str, list] = {}
        for name, p in parts.items():
            self._bodies[name] = self._new(*body_triangles(p), emb.QUALITY_HIGH)
            self._n_boxes += 0 if p.mesh_file is not None else len(p.half_extents)
            self._tilted[name] = [None, slice(self._n_cyl, self._n_cyl + len(p.cyl_radius))]
            self._n_cyl += len(p.cyl_radius)
        self._cubes: list[_Proto] = []
        self._prisms: list[_Proto] = []
        self._table()

    def _new(self, v: np.ndarray, f: np.ndarray, quality: int) -> _Proto:
        proto = _Proto(self._dev, self._top, len(self._protos), v, f, quality)
        self._protos.append(proto)
        self._owner = None
        return proto

    def _table(self) -> None:
        """Every prototype's planes in one table (``_planes_all`` (P, 4), prototype k's rows from
        ``_base[k]``; ``_owner`` (P,): the prototype of each row); the grain surface's rows are unused."""
        self._base = np.zeros(len(self._protos) + 1, np.int64)
        self._base[1:] = np.cumsum([len(p.planes) for p in self._protos])
        self._planes_all = np.concatenate([p.planes for p in self._protos])
        self._owner = np.repeat(np.arange(len(self._protos)), [len(p.planes) for p in self._protos])

    def _pool(self, pool: list[_Proto], unit: str, n: int) -> list[_Proto]:
        """The first ``n`` instances of a unit solid's pool (grown as needed), the rest hidden."""
        while len(pool) < n:
            pool.append(self._new(*self._unit[unit], emb.QUALITY_HIGH))
        for proto in pool[n:]:
            proto.hide()
        return pool[:n]

    def _heightfield(self, scene: Scene) -> None:
        """The grain surface's vertex heights for this frame, refitted (the grid made on first use or when it
        changes); ``_hf_v`` (V, 3) float64 grid-frame vertices, ``_hf_z`` (V,) their heights, ``_hf_f`` (F, 3)
        faces, ``_hf_terms`` (F, 7) their planes' terms that the heights leave alone (:func:`_grid_terms`)."""
        hf = scene.heightfield
        nx, ny = hf.heights.shape
        key = (nx, ny, hf.cell_m, hf.length_m, hf.width_m)
        padded = padded_heights(np.asarray(hf.heights, np.float64)).ravel()
        if key != self._hf_key:
            xy = grid_vertices(nx, ny, hf.cell_m, hf.length_m, hf.width_m, np.float64)
            self._hf_v, self._hf_f = np.column_stack([xy, padded]), grid_triangles(nx, ny).astype(np.int64)
            self._hf_terms, self._hf_z = _grid_terms(self._hf_v, self._hf_f), padded
            if self._hf is not None:                        # another grid: the old surface is left hidden
                self._hf.hide()
                self._hf.planes = np.zeros((0, 4))
            self._hf = self._new(self._hf_v, self._hf_f, emb.QUALITY_REFIT)
            self._hf_key = key
        elif not np.array_equal(self._hf_v[:, 2], padded):     # unchanged heights: the BVH stands
            self._hf_v[:, 2] = padded
            self._hf_z = padded
            self._hf.geom.buffers[0][:-1, 2] = padded
            emb.refit(self._hf.geom)
            emb.api().rtcCommitScene(self._hf.scene)

    def _meshes(self, scene: Scene) -> list[tuple[_Proto, np.ndarray]]:
        """(prototype, world_from_mesh) of the scene's meshes that are no entity's (the terrain's patch,
        cosim.world.terrain): one refittable prototype per vertex and face count, its vertices rewritten and
        refitted when a mesh of another name arrives; the others hidden."""
        used = []
        for mesh in scene.meshes:
            if mesh.name in self._bodies:
                continue
            key = (len(mesh.vertices), len(mesh.faces))
            if key not in self._extra:
                v = np.asarray(mesh.vertices, np.float64)
                self._extra[key] = [self._new(v, np.asarray(mesh.faces, np.int64), emb.QUALITY_REFIT), mesh.name]
            proto, name = self._extra[key]
            if name != mesh.name:
                v = np.asarray(mesh.vertices, np.float64)
                proto.geom.buffers[0][:-1, :3] = v
                emb.refit(proto.geom)
                emb.api().rtcCommitScene(proto.scene)
                proto.planes = _planes(v, np.asarray(mesh.faces, np.int64))
                self._owner = None                          # the plane table is rebuilt
                self._extra[key][1] = mesh.name
            used.append((proto, mesh.world_from_mesh))
        for proto, _ in self._extra.values():
            if all(proto is not u for u, _ in used):
                proto.hide()
        return used

    def _place_bodies(self, scene: Scene, tilted: list[str], o: np.ndarray, lin: np.ndarray,
                      trans: np.ndarray) -> list[int]:
        """Each machine body's placement (origin-relative) into ``lin`` (K, 3, 3) and ``trans`` (K, 3), a tilted one
        by its boxes-only prototype (the other one hidden); the prototypes' indices."""
        idx = []
        for name, proto in self._bodies.items():
            boxes_only = self._tilted[name][0]
            if name in tilted:
                proto.hide()
                proto = boxes_only
            elif boxes_only is not None:
                boxes_only.hide()
            k = proto.k
            lin[k], trans[k] = scene.poses[name][:3, :3], scene.poses[name][:3, 3] - o
            idx.append(k)
        return idx

    def _place(self, ks: np.ndarray, lin: np.ndarray, trans: np.ndarray) -> None:
        """Place prototypes ``ks`` (M,) at their ``lin`` and ``trans`` (rows k), their float32 transforms made in
        one pass; an instance shown and already at that transform (to the bit) is left as it is."""
        m = np.empty((len(ks), 4, 3), np.float32)         # Embree's column-major 3 x 4: lin's columns, trans
        m[:, :3] = lin[ks].transpose(0, 2, 1)
        m[:, 3] = trans[ks]
        protos = [self._protos[k] for k in ks.tolist()]
        if not protos:
            return
        last = np.stack([p.inst.buffers[0] for p in protos])
        same = (last.view(np.uint32) == m.view(np.uint32)).all(axis=(1, 2))
        for proto, m_k, keep in zip(protos, m, same.tolist()):
            if not (keep and proto.enabled):
                proto.place_packed(m_k)

    def cast(self, scene: Scene, origin: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """Exact ranges (N,) float64 m (inf on a miss) of rays from ``origin`` (3,) along unit ``directions``
        (N, 3), world frame, through ``scene`` (built by ``scene_from_state`` for this caster's scenario)."""
        if scene.poses is None:
            raise ValueError("the scene has no entity poses (build it with scene_from_state)")
        o = np.asarray(origin, np.float64).reshape(3)
        d = np.ascontiguousarray(directions, dtype=np.float64).reshape(-1, 3)
        self._heightfield(scene)
        b, c = scene.boxes, scene.cylinders
        cubes = self._pool(self._cubes, "cube", len(b) - self._n_boxes)
        tilted = [n for n in self._bodies if scene.poses[n][2, 0] != 0.0 or scene.poses[n][2, 1] != 0.0]
        dyn = slice(self._n_cyl, len(c))
        if tilted:
            dyn = np.concatenate([np.arange(len(c))[self._tilted[n][1]] for n in tilted] + [np.arange(len(c))[dyn]])
        prisms = self._pool(self._prisms, "prism", len(c.radius[dyn]))
        for n in tilted:
            if self._tilted[n][0] is None:
                self._tilted[n][0] = self._new(*body_triangles(self._parts[n], cylinders=False), emb.QUALITY_HIGH)
        meshes = self._meshes(scene)
        if self._owner is None:
            self._table()
        # every prototype's placement (origin-relative): lin (K, 3, 3), trans (K, 3); hidden ones stay identity
        lin = np.tile(np.eye(3), (len(self._protos), 1, 1))
        trans = np.zeros((len(self._protos), 3))
        hf = scene.heightfield
        idx = [self._hf.k]
        lin[idx[0]], trans[idx[0]] = hf.world_from_grid[:3, :3], hf.world_from_grid[:3, 3] - o
        idx += self._place_bodies(scene, tilted, o, lin, trans)
        ks = [p.k for p in cubes]
        m = b.world_from_box[self._n_boxes:]
        lin[ks], trans[ks] = m[:, :3, :3] * b.half_extents[self._n_boxes:, None, :], m[:, :3, 3] - o
        idx += ks
        ks = [p.k for p in prisms]
        axis = c.p1[dyn] - c.p0[dyn]
        if ks:
            lin[ks] = orthonormal_frames(axis) * np.stack([c.radius[dyn], c.radius[dyn],
                                                           np.linalg.norm(axis, axis=1)], axis=1)[:, None, :]
            trans[ks] = c.p0[dyn] - o
        idx += ks
        for proto, m in meshes:
            k = proto.k
            lin[k], trans[k] = m[:3, :3], m[:3, 3] - o
            idx.append(k)
        ground, ground_k = None, -1
        if scene.ground_box is not None and scene.ground_box >= self._n_boxes:
            ground = top_face_from_above(b.world_from_box[scene.ground_box], b.half_extents[scene.ground_box], o, d)
            if ground is not None:                         # the ground is the plane below: tfar, not a solid
                ground_k = cubes[scene.ground_box - self._n_boxes].k
        idx = np.asarray(idx, np.int64)
        solid = has_volume(lin[idx], trans[idx])
        lin[idx[~solid]], trans[idx[~solid]] = np.eye(3), 0.0     # no volume: hidden, never inverted
        cast = solid & (idx != ground_k)
        for k in idx[~cast].tolist():
            self._protos[k].hide()
        self._place(idx[cast], lin, trans)
        self._top_obj.is_committed = 0                     # run() commits the top scene
        tfar = None
        if ground is not None:                             # a hit before the ground is all Embree must find
            tfar = np.where(np.isfinite(ground), ground * (1.0 + _TFAR_SLACK) + _TFAR_SLACK, _NO_HIT).astype(np.float32)
        out = self._top_obj.run(np.zeros(d.shape, np.float32), d.astype(np.float32), dists=tfar, output=True)
        t = self._ranges(out, d, lin, trans)
        return t if ground is None else np.minimum(t, ground)

    def _ranges(self, out: dict, d: np.ndarray, lin: np.ndarray, trans: np.ndarray) -> np.ndarray:
        """The float64 range of each hit: the ray (from the origin, along ``d``) against its triangle's plane
        n . x = c placed in the world by x_w = lin x + trans: n_w = lin^-T n, c_w = c + n_w . trans,
        t = c_w / (n_w . d). The placed planes are computed once per distinct triangle hit (the grain surface's
        from its vertices of this frame), not for every triangle of the scene."""
        t = np.full(len(d), np.inf)
        geom = out["geomID"]
        hit = np.flatnonzero((geom >= 0) & (out["tfar"] < _MISS_M))
        if hit.size == 0:
            return t
        rows = np.take(self._base, np.take(geom, hit)) + np.take(out["primID"], hit)    # (H,) table rows
        used, inverse = _distinct(rows, len(self._planes_all))
        own = self._owner[used]
        planes = self._planes_all[used]                                     # (U, 4) copies: the table is kept
        k_hf = self._hf.k
        on_hf = np.flatnonzero(own == k_hf)
        if on_hf.size:
            faces = used[on_hf] - self._base[k_hf]
            planes[on_hf] = _grid_planes_at(np.take(self._hf_terms, faces, axis=0), self._hf_z,
                                            np.take(self._hf_f, faces, axis=0))
        placed = np.flatnonzero(np.bincount(own, minlength=len(lin)))      # the prototypes hit
        at = np.zeros(len(lin), np.intp)
        at[placed] = np.arange(len(placed))
        inv = np.linalg.inv(lin[placed])[at[own]]                           # (U, 3, 3)
        table = np.empty((len(used), 5))                            # n_w, c_w, graze threshold
        table[:, :3] = np.einsum("pi,pij->pj", planes[:, :3], inv)
        table[:, 3] = planes[:, 3] + np.einsum("pi,pi->p", table[:, :3], trans[own])
        table[:, 4] = _GRAZE * np.sqrt(np.einsum("pi,pi->p", table[:, :3], table[:, :3]))
        nx, ny, nz, c, graze = (np.take(col, inverse) for col in table.T.copy())     # (H,) each
        dh = np.take(d, hit, axis=0)                                        # (H, 3)
        nd = nx * dh[:, 0] + ny * dh[:, 1] + nz * dh[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            t_hit = np.where(np.abs(nd) > graze, c / nd, np.take(out["tfar"], hit))
        t[hit] = np.where(t_hit > T_MIN_M, t_hit, np.inf)
        return t

    def _ranges_every_plane(self, out: dict, d: np.ndarray, lin: np.ndarray, trans: np.ndarray) -> np.ndarray:
        """:meth:`_ranges` written plainly, its reference: every triangle's plane of every prototype placed in the
        world, then each hit's looked up (the same arithmetic per plane and per hit; tested bit for bit)."""
        t = np.full(len(d), np.inf)
        geom, prim = out["geomID"], out["primID"]
        hit = np.flatnonzero((geom >= 0) & (out["tfar"] < _MISS_M))
        if hit.size == 0:
            return t
        k_hf = self._hf.k
        planes = self._planes_all.copy()
        planes[self._base[k_hf]:self._base[k_hf + 1]] = _grid_planes(self._hf_v, self._hf_f)
        inv = np.linalg.inv(lin)
        own = self._owner
        table = np.empty((len(planes), 5))
        table[:, :3] = np.einsum("pi,pij->pj", planes[:, :3], inv[own])
        table[:, 3] = planes[:, 3] + np.einsum("pi,pi->p", table[:, :3], trans[own])
        table[:, 4] = _GRAZE * np.sqrt(np.einsum("pi,pi->p", table[:, :3], table[:, :3]))
        sel = table[self._base[geom[hit]] + prim[hit]]
        dh = d[hit]
        nd = sel[:, 0] * dh[:, 0] + sel[:, 1] * dh[:, 1] + sel[:, 2] * dh[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            t_hit = np.where(np.abs(nd) > sel[:, 4], sel[:, 3] / nd, out["tfar"][hit])
        t[hit] = np.where(t_hit > T_MIN_M, t_hit, np.inf)
        return t

    def close(self) -> None:
        """Release the top scene with its instances, then the prototype scenes and their shared buffers."""
        self._top_obj = self._device_obj = None
        self._bodies.clear()
        self._finalizer()
