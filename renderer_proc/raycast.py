"""Exact ray casting of a :class:`~renderer_proc.scene.Scene` (numpy, vectorised).

The reference that perception accuracy is measured against and the core of the mock renderer. Every
primitive is intersected in closed form: boxes by slabs, cylinders as the capped regular prisms the GL renderer
draws (``renderer_proc.meshes.CYLINDER_SIDES`` facets; the scene's cylinders are defined as those prisms),
the grain height field as the exact triangulated surface the GL renderer draws (``renderer_proc.heightfield``),
meshes by Moller-Trumbore. Rays are world frame: ``origins`` (N, 3) m and unit ``directions`` (N, 3); the
result ``t`` (N,) float64 is the distance in m to the first hit with t > 0, ``inf`` on a miss.
"""
from __future__ import annotations

import numpy as np

from .heightfield import padded_heights, surface_height
from .meshes import CYLINDER_SIDES, orthonormal_frames
from .scene import Boxes, Cylinders, HeightField, MeshInstance, Scene

__all__ = ["raycast", "ray_boxes", "ray_cylinders", "ray_heightfield", "ray_mesh", "T_MIN_M"]

#: hits closer than this along the ray are ignored (self-intersection guard), m
T_MIN_M = 1e-9
#: cylinders per bounding-sphere group in the two-level cull
_CYL_GROUP = 8
#: triangles per chunk in the mesh intersector
_TRI_CHUNK = 256


def _first_positive(t_lo: np.ndarray, t_hi: np.ndarray, hit: np.ndarray) -> np.ndarray:
    """Entry distance, or exit distance when the origin is inside; inf where not ``hit`` or behind."""
    t = np.where(t_lo > T_MIN_M, t_lo, t_hi)
    return np.where(hit & (t > T_MIN_M), t, np.inf)


def ray_boxes(o: np.ndarray, d: np.ndarray, boxes: Boxes) -> np.ndarray:
    """Distance to the nearest oriented box (slab test in each box frame). o, d (N, 3) -> t (N,)."""
    if len(boxes) == 0:
        return np.full(len(o), np.inf)
    nb = len(boxes)
    r = boxes.world_from_box[:, :3, :3]                                 # (B, 3, 3)
    c = boxes.world_from_box[:, :3, 3]                                  # (B, 3)
    r_all = np.transpose(r, (1, 0, 2)).reshape(3, 3 * nb)               # [R_0 | R_1 | ...]
    ob = (o @ r_all).reshape(-1, nb, 3) - np.einsum("bj,bji->bi", c, r)[None]   # (N, B, 3) box frame
    db = (d @ r_all).reshape(-1, nb, 3)
    h = boxes.half_extents[None]
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / db
        t1, t2 = (-h - ob) * inv, (h - ob) * inv
    t_lo = np.nanmax(np.minimum(t1, t2), axis=2)
    t_hi = np.nanmin(np.maximum(t1, t2), axis=2)
    return _first_positive(t_lo, t_hi, t_hi >= t_lo).min(axis=1)


def _prism_pairs(o, d, p0, p1, radius) -> np.ndarray:
    """Exact distance to the capped regular prism the GL renderer draws for each cylinder (CYLINDER_SIDES
    facets, vertices on the circle, local frame from ``orthonormal_frames``), for paired rows: o, d, p0, p1
    (K, 3), radius (K,) -> t (K,). Convex: the ray is inside every facet's half-space between t_lo and t_hi."""
    axis = p1 - p0
    length = np.linalg.norm(axis, axis=1)
    rot = orthonormal_frames(axis)                                   # (K, 3, 3), columns x, y, axis
    ol = np.einsum("kji,kj->ki", rot, o - p0)
    dl = np.einsum("kji,kj->ki", rot, d)
    phi = 2.0 * np.pi * (np.arange(CYLINDER_SIDES) + 0.5) / CYLINDER_SIDES
    nrm = np.stack([np.cos(phi), np.sin(phi)], axis=1)               # (S, 2) facet normals
    num = (radius * np.cos(np.pi / CYLINDER_SIDES))[:, None] - ol[:, :2] @ nrm.T   # (K, S)
    den = dl[:, :2] @ nrm.T
    num = np.concatenate([num, (length - ol[:, 2])[:, None], ol[:, 2:3]], axis=1)
    den = np.concatenate([den, dl[:, 2:3], -dl[:, 2:3]], axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = num / den
    t_lo = np.max(np.where(den < 0.0, t, -np.inf), axis=1)
    t_hi = np.min(np.where(den > 0.0, t, np.inf), axis=1)
    parallel_out = np.any((den == 0.0) & (num < 0.0), axis=1)
    return _first_positive(t_lo, t_hi, (t_hi >= t_lo) & ~parallel_out)


def _sphere_hit(o, d, centre, rad) -> np.ndarray:
    """(N, G) bool: ray n passes within ``rad`` (G,) of ``centre`` (G, 3) ahead of its origin (or inside)."""
    m = centre[None] - o[:, None]                              # (N, G, 3)
    tc = np.einsum("ngi,ni->ng", m, d)
    dist2 = np.einsum("ngi,ngi->ng", m, m) - tc**2
    return (dist2 <= rad[None] ** 2) & (tc + rad[None] > 0.0)


def ray_cylinders(o: np.ndarray, d: np.ndarray, cyl: Cylinders) -> np.ndarray:
    """Distance to the nearest capped cylinder, culled by group then per-cylinder bounding spheres."""
    n, m = len(o), len(cyl)
    best = np.full(n, np.inf)
    if m == 0:
        return best
    centre = 0.5 * (cyl.p0 + cyl.p1)
    rad = np.sqrt((0.5 * np.linalg.norm(cyl.p1 - cyl.p0, axis=1)) ** 2 + cyl.radius**2)
    for g0 in range(0, m, _CYL_GROUP):
        sl = slice(g0, min(g0 + _CYL_GROUP, m))
        gc = centre[sl].mean(axis=0)
        gr = np.max(np.linalg.norm(centre[sl] - gc, axis=1) + rad[sl])
        rays = np.nonzero(_sphere_hit(o, d, gc[None], np.array([gr]))[:, 0])[0]
        if len(rays) == 0:
            continue
        ri, ci = np.nonzero(_sphere_hit(o[rays], d[rays], centre[sl], rad[sl]))
        if len(ri) == 0:
            continue
        ri, ci = rays[ri], ci + g0
        t = _prism_pairs(o[ri], d[ri], cyl.p0[ci], cyl.p1[ci], cyl.radius[ci])
        np.minimum.at(best, ri, t)
    return best


def _grid_breaks(ox, oy, dx, dy, hf: HeightField, nx: int, ny: int) -> np.ndarray:
    """(K, L) ray parameters where the ray crosses the grid lines and diagonals of the triangulation."""
    c = hf.cell_m
    xs = (np.arange(1, nx + 1) - 0.5) * c
    ys = (np.arange(1, ny + 1) - 0.5) * c
    ks = np.arange(-ny - 1, nx + 2) * c
    with np.errstate(divide="ignore", invalid="ignore"):
        tx = (xs[None] - ox[:, None]) / dx[:, None]
        ty = (ys[None] - oy[:, None]) / dy[:, None]
        tk = (ks[None] - (ox - oy)[:, None]) / (dx - dy)[:, None]
    return np.concatenate([tx, ty, tk], axis=1)


def ray_heightfield(o: np.ndarray, d: np.ndarray, hf: HeightField) -> np.ndarray:
    """Distance to the triangulated grain surface (exact: the surface is linear between breakpoints)."""
    n = len(o)
    best = np.full(n, np.inf)
    g_from_w = np.linalg.inv(hf.world_from_grid)
    og = o @ g_from_w[:3, :3].T + g_from_w[:3, 3]
    dg = d @ g_from_w[:3, :3].T
    h = np.asarray(hf.heights, dtype=np.float64)
    lo = np.array([0.0, 0.0, float(h.min())])
    hi = np.array([hf.length_m, hf.width_m, float(h.max())])
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = (lo - og) / dg, (hi - og) / dg
    t_lo = np.maximum(np.nanmax(np.minimum(t1, t2), axis=1), 0.0)
    t_hi = np.nanmin(np.maximum(t1, t2), axis=1)
    cand = np.nonzero(t_hi >= t_lo)[0]
    if len(cand) == 0:
        return best
    oc, dc, a, b = og[cand], dg[cand], t_lo[cand], t_hi[cand]
    nx, ny = h.shape
    brk = _grid_breaks(oc[:, 0], oc[:, 1], dc[:, 0], dc[:, 1], hf, nx, ny)
    brk = np.where(np.isfinite(brk), np.clip(brk, a[:, None], b[:, None]), b[:, None])
    ts = np.sort(np.concatenate([a[:, None], brk, b[:, None]], axis=1), axis=1)   # (K, L + 2)
    px = oc[:, 0:1] + ts * dc[:, 0:1]
    py = oc[:, 1:2] + ts * dc[:, 1:2]
    g = oc[:, 2:3] + ts * dc[:, 2:3] - surface_height(padded_heights(h), hf.cell_m, px, py)
    below = g <= 0.0
    hit = below.any(axis=1)
    k = np.argmax(below, axis=1)
    rows = np.arange(len(cand))
    km = np.maximum(k - 1, 0)
    g0, g1 = g[rows, km], g[rows, k]
    t0, t1_ = ts[rows, km], ts[rows, k]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(k == 0, t0, t0 + g0 * (t1_ - t0) / (g0 - g1))
    best[cand] = np.where(hit & (t > T_MIN_M), t, np.inf)
    return best


def ray_mesh(o: np.ndarray, d: np.ndarray, mesh: MeshInstance) -> np.ndarray:
    """Distance to a triangle mesh (Moller-Trumbore, two-sided), culled by the mesh's bounding box."""
    best = np.full(len(o), np.inf)
    v = mesh.vertices @ mesh.world_from_mesh[:3, :3].T + mesh.world_from_mesh[:3, 3]
    lo, hi = v.min(axis=0), v.max(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = (lo - o) / d, (hi - o) / d
    t_hi = np.nanmin(np.maximum(t1, t2), axis=1)
    rays = np.nonzero(t_hi >= np.maximum(np.nanmax(np.minimum(t1, t2), axis=1), 0.0))[0]
    tri = v[mesh.faces]
    for c0 in range(0, len(tri), _TRI_CHUNK):
        p0, e1, e2 = tri[c0:c0 + _TRI_CHUNK, 0], tri[c0:c0 + _TRI_CHUNK, 1], tri[c0:c0 + _TRI_CHUNK, 2]
        e1, e2 = e1 - p0, e2 - p0
        dr = d[rays][:, None]
        pv = np.cross(dr, e2[None])
        det = np.einsum("nti,ti->nt", pv, e1)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            tv = o[rays][:, None] - p0[None]
            u = np.einsum("nti,nti->nt", tv, pv) * inv
            qv = np.cross(tv, e1[None])
            vv = np.einsum("nti,nti->nt", np.broadcast_to(dr, qv.shape), qv) * inv
            t = np.einsum("ti,nti->nt", e2, qv) * inv
        ok = (np.abs(det) > 1e-14) & (u >= 0) & (vv >= 0) & (u + vv <= 1) & (t > T_MIN_M)
        best[rays] = np.minimum(best[rays], np.where(ok, t, np.inf).min(axis=1))
    return best


def raycast(scene: Scene, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """First hit along unit rays: ``origins`` (N, 3), ``directions`` (N, 3) world frame -> t (N,) float64 m,
    ``inf`` on a miss."""
    o = np.ascontiguousarray(origins, dtype=np.float64).reshape(-1, 3)
    d = np.ascontiguousarray(directions, dtype=np.float64).reshape(-1, 3)
    if o.shape != d.shape:
        o = np.broadcast_to(o, d.shape)
    t = np.minimum(ray_boxes(o, d, scene.boxes), ray_cylinders(o, d, scene.cylinders))
    t = np.minimum(t, ray_heightfield(o, d, scene.heightfield))
    for mesh in scene.meshes:
        t = np.minimum(t, ray_mesh(o, d, mesh))
    return t
