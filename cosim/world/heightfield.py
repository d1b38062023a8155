"""The drawn grain surface: one triangulated height field shared by the GL renderer and the ray caster.

Cart grid frame (docs/architecture.md): x along the cart 0..L, y across 0..W, z up from the floor. The grain
model's cells (i, j) are centred at ((i + 0.5) c, (j + 0.5) c). The surface interpolates the cell heights
linearly between cell centres, on a vertex grid at the cell centres padded by one edge-replicated ring:
vertex (a, b), a = 0..nx+1, b = 0..ny+1, stands at x = (a - 0.5) c, y = (b - 0.5) c with height
``padded[a, b]`` = h[clip(a - 1), clip(b - 1)]. Every grid quad is split along its (a, b)-(a+1, b+1) diagonal.
The surface is then clipped to the interior [0, L] x [0, W]; because the padded ring is edge-replicated, the
outer half cells are flat across the wall normal, so clamping their vertices to the walls keeps the surface
exactly the same (this is what the GL mesh does).

Within a quad with local coordinates (fx, fy) in [0, 1]^2 the height is
    fx >= fy:  z = h00 + fx (h10 - h00) + fy (h11 - h10)
    fx <  fy:  z = h00 + fy (h01 - h00) + fx (h11 - h01)
which is continuous and piecewise linear: along a ray it is linear between the crossings of the grid lines
x = (a - 0.5) c, y = (b - 0.5) c and the diagonals x - y = k c. The ray caster uses exactly this.
"""
from __future__ import annotations

import numpy as np

__all__ = ["grid_triangles", "grid_vertices", "padded_heights", "surface_height"]


def padded_heights(heights: np.ndarray) -> np.ndarray:
    """(nx, ny) cell heights -> (nx + 2, ny + 2) vertex heights with an edge-replicated ring, same dtype
    (``np.pad(h, 1, mode="edge")``, written out: it runs every frame and np.pad's overhead is most of it)."""
    h = np.asarray(heights)
    out = np.empty((h.shape[0] + 2, h.shape[1] + 2), dtype=h.dtype)
    out[1:-1, 1:-1] = h
    out[0, 1:-1], out[-1, 1:-1] = h[0], h[-1]
    out[:, 0], out[:, -1] = out[:, 1], out[:, -2]
    return out


def surface_height(padded: np.ndarray, cell_m: float, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Height of the triangulated surface at grid-frame points ``x``, ``y`` (any equal shape, m).

    ``padded``: (nx + 2, ny + 2) vertex heights from :func:`padded_heights`. Points are clamped into the padded
    grid, so any x in [0, L], y in [0, W] is valid. Returns float64 of the shape of ``x``.
    """
    hp = np.asarray(padded, dtype=np.float64)
    na, nb = hp.shape
    gx = np.clip(np.asarray(x, dtype=np.float64) / cell_m + 0.5, 0.0, na - 1.0)
    gy = np.clip(np.asarray(y, dtype=np.float64) / cell_m + 0.5, 0.0, nb - 1.0)
    # the cell corner as float (exact small integers) for the fractions, as int for the gathers
    af, bf = np.minimum(np.floor(gx), na - 2.0), np.minimum(np.floor(gy), nb - 2.0)
    fx, fy = gx - af, gy - bf
    a, b = af.astype(np.intp), bf.astype(np.intp)
    # the four corners by flat index (a, b in range by the clip: one cheap gather each, not a 2-D fancy index)
    flat = hp.ravel()
    k = a * nb + b
    h00, h10 = np.take(flat, k, mode="wrap"), np.take(flat, k + nb, mode="wrap")
    h01, h11 = np.take(flat, k + 1, mode="wrap"), np.take(flat, k + nb + 1, mode="wrap")
    lower = h00 + fx * (h10 - h00) + fy * (h11 - h10)
    upper = h00 + fy * (h01 - h00) + fx * (h11 - h01)
    return np.where(fx >= fy, lower, upper)


def grid_vertices(nx: int, ny: int, cell_m: float, length_m: float, width_m: float,
                  dtype=np.float32) -> np.ndarray:
    """(nx + 2) * (ny + 2) vertex (x, y) positions of ``dtype`` (float32 for GL; grid frame, m), row-major in
    (a, b), clamped to the interior [0, L] x [0, W]. Vertex k = a * (ny + 2) + b takes height
    ``padded.ravel()[k]``."""
    xs = np.clip((np.arange(nx + 2) - 0.5) * cell_m, 0.0, length_m)
    ys = np.clip((np.arange(ny + 2) - 0.5) * cell_m, 0.0, width_m)
    xx, yy = np.meshgrid(xs, ys, indexing="ij")
    return np.stack([xx.ravel(), yy.ravel()], axis=1).astype(dtype)


def grid_triangles(nx: int, ny: int) -> np.ndarray:
    """Triangle vertex indices (2 (nx + 1) (ny + 1), 3) int32 for :func:`grid_vertices`, each quad split along
    its (a, b)-(a+1, b+1) diagonal as :func:`surface_height` assumes."""
    nb = ny + 2
    a, b = np.meshgrid(np.arange(nx + 1), np.arange(ny + 1), indexing="ij")
    v00 = (a * nb + b).ravel()
    v10, v01, v11 = v00 + nb, v00 + 1, v00 + nb + 1
    lower = np.stack([v00, v10, v11], axis=1)   # fx >= fy
    upper = np.stack([v00, v11, v01], axis=1)   # fx < fy
    return np.concatenate([lower, upper]).astype(np.int32)
