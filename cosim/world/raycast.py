"""Exact ray casting of a :class:`~cosim.world.scene.Scene` (numpy, vectorised).

The reference that perception accuracy is measured against and the core of the mock renderer. Every
primitive is intersected in closed form: boxes by slabs, cylinders as the capped regular prisms the GL renderer
draws (``cosim.world.meshes.CYLINDER_SIDES`` facets; the scene's cylinders are defined as those prisms),
the grain height field as the exact triangulated surface the GL renderer draws (``cosim.world.heightfield``),
meshes by Moller-Trumbore. Rays are world frame: ``origins`` (N, 3) m and unit ``directions`` (N, 3); the
result ``t`` (N,) float64 is the distance in m to the first hit with t > 0, ``inf`` on a miss.
"""
from __future__ import annotations

import numpy as np

from .heightfield import padded_heights, surface_height
from .meshes import CYLINDER_SIDES, orthonormal_frames
from .scene import Boxes, Cylinders, HeightField, MeshInstance, Scene

__all__ = ["T_MIN_M", "ray_boxes", "ray_cylinders", "ray_heightfield", "ray_mesh", "raycast"]

#: hits closer than this along the ray are ignored (self-intersection guard), m
T_MIN_M = 1e-9
#: primitives per bounding-sphere group in the two-level cull
_GROUP = 8
#: (ray, primitive) tests per block in the shared-origin cull and prism test (bounds the work arrays)
_PAIR_WORK = 1 << 18
#: slack on bounding-sphere radii (relative and m) and cosines in the culls: rounding never culls a hit
_CULL_SLACK = 1e-9
#: triangles per chunk in the mesh intersector
_TRI_CHUNK = 256
#: vertical padding of the height field's bounding slab, m
_HF_Z_PAD_M = 1e-3
#: rays per chunk in the height-field intersector
_HF_CHUNK = 4096


def _first_positive(t_lo: np.ndarray, t_hi: np.ndarray, hit: np.ndarray) -> np.ndarray:
    """Entry distance, or exit distance when the origin is inside; inf where not ``hit`` or behind."""
    t = np.where(t_lo > T_MIN_M, t_lo, t_hi)
    return np.where(hit & (t > T_MIN_M), t, np.inf)


def _convex_pairs(ol, dl, normals, offsets) -> np.ndarray:
    """Ray vs convex polyhedron {p : n_j . p <= offset_j}, in its local frame, for paired rows.

    ``ol``, ``dl`` (K, 3) local ray origins and directions; ``normals`` (P, 3) outward unit normals;
    ``offsets`` (K, P) m. Returns t (K,): entry (or exit when inside), inf on a miss."""
    return _convex_t(offsets - ol @ normals.T, dl @ normals.T)


def _convex_t(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    """The clipping of :func:`_convex_pairs` from ``num`` = offset - n . o and ``den`` = n . d, (K, P) each."""
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        t = num / den
    t_lo = np.max(np.where(den < 0.0, t, -np.inf), axis=1)
    t_hi = np.min(np.where(den > 0.0, t, np.inf), axis=1)
    parallel_out = np.any((den == 0.0) & (num < 0.0), axis=1)
    return _first_positive(t_lo, t_hi, (t_hi >= t_lo) & ~parallel_out)


def _shared_origin(o: np.ndarray) -> np.ndarray | None:
    """The common origin (3,) when every ray starts at the same point (a camera, the LiDAR), else None."""
    if len(o) == 0:
        return None
    if o.strides[0] == 0 or not np.any(o != o[0]):
        return np.array(o[0], dtype=np.float64)
    return None


def _cone_pairs(origin, d, centres, radii, best) -> tuple[np.ndarray, np.ndarray]:
    """(primitive, ray) index pairs, (P,) int64 each, sorted by primitive then ray, of rays from one ``origin``
    (3,) along ``d`` (N, 3) that pass within a bounding sphere (``centres`` (K, 3), ``radii`` (K,), m) and
    could enter it before their ``best`` (N,).

    From a common origin the sphere test is angular, d . u >= cos(asin(radius / distance)) with u the unit
    direction to the centre (every ray when the origin is inside): one matrix product per block of rays for
    all primitives at once. Radii and cosines carry :data:`_CULL_SLACK`, so the cull is conservative."""
    m = centres - origin
    dist = np.linalg.norm(m, axis=1)
    rad = radii * (1.0 + _CULL_SLACK) + _CULL_SLACK
    inside = dist <= rad
    scale = np.where(inside, 1.0, dist)                 # u is unit outside a sphere, m itself inside it
    u = m / scale[:, None]
    with np.errstate(invalid="ignore", divide="ignore"):
        cos_half = np.where(inside, -np.inf, np.sqrt(np.maximum(1.0 - (rad / dist) ** 2, 0.0)) - _CULL_SLACK)
    ks, rs = [], []
    step = max(1, _PAIR_WORK // max(len(centres), 1))
    for s0 in range(0, len(d), step):
        dots = u @ d[s0:s0 + step].T                                   # (K, B): cosines to each centre
        # flat indices, then (primitive, ray): np.nonzero on a 2-D mask costs several times more
        f = np.flatnonzero(dots >= cos_half[:, None])
        k, r = np.divmod(f, dots.shape[1])
        near = np.take(dots, f) * scale[k] - rad[k]                    # entry bound along the ray (m . d - R)
        r += s0
        keep = near < best[r]
        ks.append(k[keep])
        rs.append(r[keep])
    k, r = np.concatenate(ks), np.concatenate(rs)
    if len(ks) > 1:
        order = np.argsort(k, kind="stable")
        k, r = k[order], r[order]
    return k, r


def _sphere_rays(o, d, centre, rad: float, best) -> np.ndarray:
    """Indices of rays that pass within ``rad`` of ``centre`` and could enter it before their ``best``."""
    m = centre - o
    tc = np.einsum("ni,ni->n", m, d)
    dist2 = np.einsum("ni,ni->n", m, m) - tc * tc
    return np.nonzero((dist2 <= rad * rad) & (tc + rad > 0.0) & (tc - rad < best))[0]


def ray_boxes(o: np.ndarray, d: np.ndarray, boxes: Boxes, t_max: np.ndarray | None = None) -> np.ndarray:
    """Distance to the nearest oriented box (slab test in each box frame). o, d (N, 3) -> t (N,).

    Per box, only rays that pass its bounding sphere and could still beat the best hit so far (initially
    ``t_max`` (N,), a known nearer hit, if given) are tested; rays from one origin are culled for all boxes
    at once (:func:`_cone_pairs`)."""
    best = np.full(len(o), np.inf) if t_max is None else np.array(t_max, dtype=np.float64)
    origin = _shared_origin(o)
    if origin is not None and len(boxes):
        # one angular cull for every box; the best hits of the other primitives still prune it
        ks, rs = _cone_pairs(origin, d, boxes.world_from_box[:, :3, 3], np.linalg.norm(boxes.half_extents, axis=1),
                             best)
        bounds = np.searchsorted(ks, np.arange(len(boxes) + 1))
    for k in range(len(boxes)):
        rot, c, h = boxes.world_from_box[k, :3, :3], boxes.world_from_box[k, :3, 3], boxes.half_extents[k]
        if origin is not None:
            rays = rs[bounds[k]:bounds[k + 1]]
        else:
            rays = _sphere_rays(o, d, c, float(np.linalg.norm(h)), best)
        if len(rays) == 0:
            continue
        if origin is not None:
            # every row is origin - c (the same subtraction), without gathering the broadcast origins
            ol = np.ascontiguousarray(np.broadcast_to(origin - c, (len(rays), 3))) @ rot
        else:
            ol = (np.take(o, rays, axis=0) - c) @ rot
        dl = np.take(d, rays, axis=0) @ rot
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            inv = 1.0 / dl
            t1, t2 = (-h - ol) * inv, (h - ol) * inv
        lo, hi = np.minimum(t1, t2), np.maximum(t1, t2)     # fmax / fmin ignore the NaN of 0 * inf
        t_lo = np.fmax(np.fmax(lo[:, 0], lo[:, 1]), lo[:, 2])
        t_hi = np.fmin(np.fmin(hi[:, 0], hi[:, 1]), hi[:, 2])
        best[rays] = np.minimum(best[rays], _first_positive(t_lo, t_hi, t_hi >= t_lo))
    return best


def ray_cylinders(o: np.ndarray, d: np.ndarray, cyl: Cylinders, t_max: np.ndarray | None = None) -> np.ndarray:
    """Distance to the nearest cylinder, drawn and cast as a capped regular prism (CYLINDER_SIDES facets,
    vertices on the circle, local frame from ``orthonormal_frames``: x, y across, z along p0 -> p1).

    Culled by group, then per-cylinder bounding spheres, and by ``t_max`` (N,), a known nearer hit. Rays from
    one origin are culled for all cylinders at once (:func:`_cone_pairs`) and the prisms are clipped for all
    (ray, cylinder) pairs together."""
    best = np.full(len(o), np.inf) if t_max is None else np.array(t_max, dtype=np.float64)
    if len(cyl) == 0:
        return best
    axis = cyl.p1 - cyl.p0
    length = np.linalg.norm(axis, axis=1)
    frames = orthonormal_frames(axis)
    centre = 0.5 * (cyl.p0 + cyl.p1)
    rad = np.sqrt((0.5 * length) ** 2 + cyl.radius**2)
    phi = 2.0 * np.pi * (np.arange(CYLINDER_SIDES) + 0.5) / CYLINDER_SIDES
    normals = np.concatenate([np.stack([np.cos(phi), np.sin(phi), np.zeros_like(phi)], axis=1),
                              [[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]]])
    origin = _shared_origin(o)
    if origin is not None:
        offsets = np.zeros((len(cyl), CYLINDER_SIDES + 2))
        offsets[:, :CYLINDER_SIDES] = (cyl.radius * np.cos(np.pi / CYLINDER_SIDES))[:, None]
        offsets[:, CYLINDER_SIDES] = length
        _prisms_shared(origin, d, frames, cyl.p0, centre, rad, cyl.radius, normals, offsets, best)
        return best
    for g0 in range(0, len(cyl), _GROUP):
        sl = slice(g0, min(g0 + _GROUP, len(cyl)))
        gc = centre[sl].mean(axis=0)
        gr = float(np.max(np.linalg.norm(centre[sl] - gc, axis=1) + rad[sl]))
        grays = _sphere_rays(o, d, gc, gr, best)
        for k in range(sl.start, sl.stop):
            rays = grays[_sphere_rays(o[grays], d[grays], centre[k], rad[k], best[grays])]
            if len(rays) == 0:
                continue
            ol = (o[rays] - cyl.p0[k]) @ frames[k]
            dl = d[rays] @ frames[k]
            off = np.array([cyl.radius[k] * np.cos(np.pi / CYLINDER_SIDES)] * CYLINDER_SIDES + [length[k], 0.0])
            best[rays] = np.minimum(best[rays], _convex_pairs(ol, dl, normals, off[None]))
    return best


def _prisms_shared(origin, d, frames, p0, centre, rad, radius, normals, offsets, best) -> None:
    """Prisms (local ``frames`` (K, 3, 3), base centres ``p0`` (K, 3), bounding spheres ``centre``, ``rad``,
    circumradii ``radius`` (K,), facet ``normals`` (F, 3) and ``offsets`` (K, F)) against rays from one
    ``origin``: ``best`` (N,) lowered in place, vectorised over (ray, prism) pairs. The local origin and n . o are
    per prism, computed once."""
    ks, rs = _cone_pairs(origin, d, centre, rad, best)
    if ks.size == 0:
        return
    ol = np.einsum("ki,kij->kj", origin - p0, frames)                  # (K, 3) the origin in each prism frame
    num_k = offsets - ol @ normals.T                                    # (K, F)
    step = max(1, _PAIR_WORK // normals.shape[0])
    # every point of a prism lies within its circumradius of its axis (local z), so a ray whose line passes
    # farther from the axis line misses it: |o_xy x d_xy| > R |d_xy| (checked with slack, a cull only)
    reach = (radius * (1.0 + _CULL_SLACK) + _CULL_SLACK)
    for s0 in range(0, ks.size, step):
        k, r = ks[s0:s0 + step], rs[s0:s0 + step]
        dl = np.einsum("pi,pij->pj", d[r], frames[k])
        o = ol[k]
        near = np.abs(o[:, 0] * dl[:, 1] - o[:, 1] * dl[:, 0]) <= reach[k] * np.hypot(dl[:, 0], dl[:, 1])
        k, r, dl = k[near], r[near], dl[near]
        np.minimum.at(best, r, _convex_t(num_k[k], dl @ normals.T))


def _line_crossings(q0, dq, a, b) -> tuple[np.ndarray, np.ndarray]:
    """For the line family q(t) = q0 + t dq crossing integers: first integer crossed in (a, b) and the count."""
    qa, qb = q0 + a * dq, q0 + b * dq
    first = np.ceil(np.minimum(qa, qb))
    count = np.maximum(np.floor(np.maximum(qa, qb)) - first + 1.0, 0.0)
    return first, count.astype(np.intp)


def _hf_chunk(og, dg, a, b, hp: np.ndarray, cell: float) -> np.ndarray:
    """First crossing of the surface for rays (K,) with windows [a, b]; inf where none.

    The height along a ray is linear between the crossings of the lines x / c + 1/2 = integer,
    y / c + 1/2 = integer and (x - y) / c = integer (``cosim.world.heightfield``), so the ray's height above
    the surface is evaluated at those crossings only, and the first sign change is solved linearly (exact).

    ``og``, ``dg`` (3, K) coordinate rows (grid frame). The work arrays are (crossings, K): each ray's values
    run down a column, so the per-ray terms broadcast along contiguous rows (no buffered broadcasting)."""
    k_rays = og.shape[1]
    fams = [(og[0] / cell + 0.5, dg[0] / cell), (og[1] / cell + 0.5, dg[1] / cell),
            ((og[0] - og[1]) / cell, (dg[0] - dg[1]) / cell)]
    cols = [a[None], b[None]]
    for q0, dq in fams:
        first, count = _line_crossings(q0, dq, a, b)
        m = int(count.max()) if len(count) else 0
        if m == 0:
            continue
        j = np.arange(m)[:, None]
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            t = (first + j.astype(np.float64) - q0) / dq  # float j: an int operand would be cast in buffers
        use = (j < count) & np.isfinite(t)                # a ray along a line (dq = 0) crosses none of it
        cols.append(np.where(use, np.clip(t, a, b), b))
    # each ray's crossings in order, down its column: sorted as contiguous rows of a transposed copy (numpy
    # sorts a strided axis element by element through a buffer)
    ts = np.ascontiguousarray(np.concatenate(cols, axis=0).T)
    ts.sort(axis=1)
    ts = np.ascontiguousarray(ts.T)
    px = og[0] + ts * dg[0]
    py = og[1] + ts * dg[1]
    g = og[2] + ts * dg[2] - surface_height(hp, cell, px, py)
    below = g <= 0.0
    k = np.argmax(below, axis=0)
    col = np.arange(k_rays)
    at = k * k_rays + col                                 # flat indices of (k, ray) and (k - 1, ray)
    before = np.maximum(k - 1, 0) * k_rays + col
    g0, g1 = np.take(g, before), np.take(g, at)
    t0, t1 = np.take(ts, before), np.take(ts, at)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        t = np.where(k == 0, t0, t0 + g0 * (t1 - t0) / (g0 - g1))
    return np.where(below.any(axis=0) & (t > T_MIN_M), t, np.inf)


def ray_heightfield(o: np.ndarray, d: np.ndarray, hf: HeightField) -> np.ndarray:
    """Distance to the triangulated grain surface (exact: the surface is linear between breakpoints).

    Rays are clipped to the box [0, L] x [0, W] x [min h, max h] (grid frame), then processed in chunks
    sorted by how many grid lines they cross, so each chunk's arrays are only as wide as it needs."""
    n = len(o)
    best = np.full(n, np.inf)
    g_from_w = np.linalg.inv(hf.world_from_grid)
    og = o @ g_from_w[:3, :3].T + g_from_w[:3, 3]
    dg = d @ g_from_w[:3, :3].T
    og, dg = np.ascontiguousarray(og.T), np.ascontiguousarray(dg.T)     # (3, N) coordinate rows
    h = np.asarray(hf.heights, dtype=np.float64)
    # the z slab is padded so that a ray leaving through its bottom is strictly below the surface there: on a
    # flat fill (min h = surface) round-off would otherwise let about half of the rays slip through
    lo = (0.0, 0.0, float(h.min()) - _HF_Z_PAD_M)
    hi = (hf.length_m, hf.width_m, float(h.max()) + _HF_Z_PAD_M)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        t1 = [(lo[i] - og[i]) / dg[i] for i in range(3)]
        t2 = [(hi[i] - og[i]) / dg[i] for i in range(3)]
    near = [np.minimum(t1[i], t2[i]) for i in range(3)]
    far = [np.maximum(t1[i], t2[i]) for i in range(3)]
    t_lo = np.maximum(np.fmax(np.fmax(near[0], near[1]), near[2]), 0.0)     # the slab test, axis by axis in order
    t_hi = np.fmin(np.fmin(far[0], far[1]), far[2])
    cand = np.nonzero(t_hi >= t_lo)[0]
    if len(cand) == 0:
        return best
    oc, dc, a, b = np.take(og, cand, axis=1), np.take(dg, cand, axis=1), t_lo[cand], t_hi[cand]
    c = hf.cell_m
    span = np.abs(dc[0]) + np.abs(dc[1])                  # line crossings grow with the xy path length
    order = np.argsort(span * (b - a))
    hp = padded_heights(h)
    for s0 in range(0, len(order), _HF_CHUNK):
        sel = order[s0:s0 + _HF_CHUNK]
        best[cand[sel]] = _hf_chunk(np.take(oc, sel, axis=1), np.take(dc, sel, axis=1), a[sel], b[sel], hp, c)
    return best


def ray_mesh(o: np.ndarray, d: np.ndarray, mesh: MeshInstance) -> np.ndarray:
    """Distance to a triangle mesh (Moller-Trumbore, two-sided), culled by the mesh's bounding box."""
    best = np.full(len(o), np.inf)
    v = mesh.vertices @ mesh.world_from_mesh[:3, :3].T + mesh.world_from_mesh[:3, 3]
    lo, hi = v.min(axis=0), v.max(axis=0)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
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
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            inv = 1.0 / det
            tv = o[rays][:, None] - p0[None]
            u = np.einsum("nti,nti->nt", tv, pv) * inv
            qv = np.cross(tv, e1[None])
            vv = np.einsum("nti,nti->nt", np.broadcast_to(dr, qv.shape), qv) * inv
            t = np.einsum("ti,nti->nt", e2, qv) * inv
            ok = (np.abs(det) > 1e-14) & (u >= 0) & (vv >= 0) & (u + vv <= 1) & (t > T_MIN_M)   # NaN: False
        best[rays] = np.minimum(best[rays], np.where(ok, t, np.inf).min(axis=1))
    return best


def raycast(scene: Scene, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """First hit along unit rays: ``origins`` (N, 3), ``directions`` (N, 3) world frame -> t (N,) float64 m,
    ``inf`` on a miss."""
    o = np.ascontiguousarray(origins, dtype=np.float64).reshape(-1, 3)
    d = np.ascontiguousarray(directions, dtype=np.float64).reshape(-1, 3)
    if o.shape != d.shape:
        o = np.broadcast_to(o, d.shape)
    # cheapest-to-cull first: every hit found bounds the search of the primitives after it
    t = ray_heightfield(o, d, scene.heightfield)
    t = ray_cylinders(o, d, scene.cylinders, t_max=t)
    t = ray_boxes(o, d, scene.boxes, t_max=t)
    for mesh in scene.meshes:
        t = np.minimum(t, ray_mesh(o, d, mesh))
    return t
