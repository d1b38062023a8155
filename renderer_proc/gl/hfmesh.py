"""The grain surface's draw mesh: the triangulated height field of ``cosim.world.heightfield`` with its flat
blocks merged into a few large triangles, and no T-junctions (pure numpy, no GL).

llvmpipe pays per triangle and per partly covered 4 x 4 pixel block, so the 2 (nx + 1) (ny + 1) small triangles of
the full grid cost several times what the same screen area costs in large triangles. The quad grid (quads
(a, b), a = 0..nx, b = 0..ny, over the padded vertex grid of :func:`~cosim.world.heightfield.grid_vertices`)
is cut into blocks of ``block`` x ``block`` quads (smaller at the far edges). Each frame:

* a block whose vertices all have one height (the untouched initial fill, an empty floor, a full plateau) is
  flat, so any triangulation of it is the same surface exactly; it is drawn as its rectangle: two triangles,
  or, when a neighbouring block is drawn fine, a fan from the block centre through every grid vertex on the
  shared sides, so that the two sides of an edge always have the same vertices (no T-junction, hence no
  crack a pixel centre could fall through);
* every other block is drawn with the grid's own triangles, each quad split along its (a, b)-(a+1, b+1)
  diagonal, exactly as the ray caster assumes.

:meth:`SurfaceMesh.triangles` gives it as a triangle list (the camera rig's GL renderer), :meth:`SurfaceMesh.quads`
as the same triangles in pairs that share an edge, four vertices each (the beam-native renderer bounds and tests a
pair at once): a fine block's grid quads, a plain block's rectangle, a fan's consecutive triangles.

Vertex buffer: the (nx + 2) (ny + 2) grid vertices (k = a (ny + 2) + b), then one centre per block. Heights
(:meth:`SurfaceMesh.heights`) follow the same order, so the surface is the same piecewise-linear function as
:func:`~cosim.world.heightfield.surface_height` (up to float32 interpolation).
"""
from __future__ import annotations

import numpy as np

from cosim.world.heightfield import grid_vertices

__all__ = ["MERGE_BLOCK", "SurfaceMesh"]

#: quads per side of a merge block: at 0.1 m cells and 3-5 m range a block is about 50 px wide at 640 x 480
MERGE_BLOCK = 4


def _bounds(n_quads: int, block: int) -> np.ndarray:
    """Block start indices along one axis plus the end: [0, block, 2 block, ..., n_quads]."""
    return np.append(np.arange(0, n_quads, block), n_quads)


class SurfaceMesh:
    """Draw mesh of an (nx, ny) cell grid (cell ``cell_m``, interior ``length_m`` x ``width_m``, m).

    ``vertices``: (V, 2) float32 grid-frame (x, y) m, V = (nx + 2) (ny + 2) + number of blocks (static).
    :meth:`heights` gives the (V,) float32 vertex heights of a frame, :meth:`triangles` its (T, 3) int32
    counter-clockwise (seen from +z) triangle list and whether it changed since the last call."""

    def __init__(self, nx: int, ny: int, cell_m: float, length_m: float, width_m: float,
                 block: int = MERGE_BLOCK):
        if block < 1:
            raise ValueError(f"merge block must be >= 1 quad, got {block}")
        self.shape = (nx, ny)
        self._nb = ny + 2                                   # vertices per grid row (index stride along a)
        self._ea, self._eb = _bounds(nx + 1, block), _bounds(ny + 1, block)
        self._na, self._nbk = len(self._ea) - 1, len(self._eb) - 1
        grid = grid_vertices(nx, ny, cell_m, length_m, width_m)
        xy = grid.reshape(nx + 2, ny + 2, 2).astype(np.float64)
        ia0, ib0 = np.meshgrid(self._ea[:-1], self._eb[:-1], indexing="ij")
        ia1, ib1 = np.meshgrid(self._ea[1:], self._eb[1:], indexing="ij")
        centres = 0.5 * (xy[ia0, ib0] + xy[ia1, ib1])       # (na, nbk, 2): inside every (non-degenerate) block
        self.vertices = np.concatenate([grid, centres.reshape(-1, 2).astype(np.float32)])
        self._n_grid = len(grid)
        self._quads = np.outer(np.diff(self._ea), np.diff(self._eb))   # quads per block
        self._pieces: dict[tuple[int, int, int, bool], np.ndarray] = {}
        self._last_key: dict[bool, bytes | None] = {False: None, True: None}     # per list: triangles, quads
        self._last: dict[bool, np.ndarray | None] = {False: None, True: None}

    @property
    def blocks(self) -> tuple[int, int]:
        """Number of blocks along a (x) and b (y)."""
        return self._na, self._nbk

    def heights(self, padded: np.ndarray) -> np.ndarray:
        """(V,) float32 vertex heights m: ``padded`` (nx + 2, ny + 2) (:func:`padded_heights`) then each block
        centre at its block's first vertex height (the block's height when it is flat; unused otherwise)."""
        hp = np.asarray(padded, dtype=np.float32)
        return np.concatenate([hp.ravel(), hp[np.ix_(self._ea[:-1], self._eb[:-1])].ravel()])

    def flat_blocks(self, padded: np.ndarray) -> np.ndarray:
        """(blocks along a, blocks along b) bool: every vertex of the block has the same height."""
        h = np.asarray(padded)
        h00 = h[:-1, :-1]
        flat_q = (h00 == h[1:, :-1]) & (h00 == h[:-1, 1:]) & (h00 == h[1:, 1:])   # (nx + 1, ny + 1) quads
        count = np.add.reduceat(np.add.reduceat(flat_q.astype(np.int32), self._ea[:-1], axis=0),
                                self._eb[:-1], axis=1)
        return count == self._quads    # all quads flat and the block connected: one height throughout

    def triangles(self, padded: np.ndarray) -> tuple[np.ndarray, bool]:
        """((T, 3) int32 triangles of this frame, whether they differ from the previous call's)."""
        return self._list(padded, quads=False)

    def quads(self, padded: np.ndarray) -> tuple[np.ndarray, bool]:
        """The same surface as :meth:`triangles` as quads: ((Q, 4) int32 corners 0 1 2 3 of this frame, whether
        they differ from the previous call's). A quad stands for its triangles 0 1 2 and 0 2 3 (the second is
        degenerate, corner 3 = corner 2, where a fan has an odd count): a fine block's grid quads (a, b) as
        vertices (a, b), (a+1, b), (a+1, b+1), (a, b+1), counter-clockwise seen from +z (the grid's own
        diagonal, as :meth:`triangles`), a plain merged block as its rectangle, a fan's triangles in pairs."""
        return self._list(padded, quads=True)

    def _list(self, padded: np.ndarray, quads: bool) -> tuple[np.ndarray, bool]:
        flat = self.flat_blocks(padded)
        key = np.packbits(flat).tobytes()
        if key == self._last_key[quads] and self._last[quads] is not None:
            return self._last[quads], False
        fine = np.pad(~flat, 1, constant_values=False)      # outside the grid: no neighbour, nothing to meet
        sides = ((fine[1:-1, :-2] * 1) | (fine[2:, 1:-1] * 2) | (fine[1:-1, 2:] * 4) | (fine[:-2, 1:-1] * 8))
        pieces = [self._piece(i, j, int(sides[i, j]) if flat[i, j] else -1, quads)
                  for i in range(self._na) for j in range(self._nbk)]
        self._last[quads] = np.concatenate(pieces).astype(np.int32, copy=False)
        self._last_key[quads] = key
        return self._last[quads], True

    def _piece(self, i: int, j: int, mode: int, quads: bool) -> np.ndarray:
        """Triangles (or quads) of block (i, j): mode -1 fine; else merged, bit k set where side k
        (b0, a1, b1, a0) must carry every grid vertex on it."""
        got = self._pieces.get((i, j, mode, quads))
        if got is None:
            got = self._make_piece(i, j, mode)
            if quads:
                got = _as_quads(got, fine=mode < 0)
            self._pieces[(i, j, mode, quads)] = got
        return got

    def _make_piece(self, i: int, j: int, mode: int) -> np.ndarray:
        a0, a1, b0, b1 = self._ea[i], self._ea[i + 1], self._eb[j], self._eb[j + 1]
        nb = self._nb

        def v(a, b):
            return np.asarray(a) * nb + np.asarray(b)

        if mode > 0:                                       # a side one quad long has no vertex between its corners
            mode &= ~(0b0101 if a1 - a0 == 1 else 0) & ~(0b1010 if b1 - b0 == 1 else 0)
        if mode < 0:                                       # the grid's own triangles, as grid_triangles
            a, b = np.meshgrid(np.arange(a0, a1), np.arange(b0, b1), indexing="ij")
            v00 = v(a, b).ravel()
            v10, v01, v11 = v00 + nb, v00 + 1, v00 + nb + 1
            return np.concatenate([np.stack([v00, v10, v11], 1), np.stack([v00, v11, v01], 1)])
        if mode == 0:                                      # plain rectangle
            return np.array([[v(a0, b0), v(a1, b0), v(a1, b1)], [v(a0, b0), v(a1, b1), v(a0, b1)]])
        # boundary loop, counter-clockwise seen from +z (a along x, b along y): b0 side, a1 side, b1 side, a0 side;
        # each side from its first corner up to (not including) the next corner
        loop = []
        for k, (pts_a, pts_b) in enumerate((
                (np.arange(a0, a1), np.full(a1 - a0, b0)),
                (np.full(b1 - b0, a1), np.arange(b0, b1)),
                (np.arange(a1, a0, -1), np.full(a1 - a0, b1)),
                (np.full(b1 - b0, a0), np.arange(b1, b0, -1)))):
            loop.append(v(pts_a, pts_b) if mode & (1 << k) else v(pts_a[:1], pts_b[:1]))
        ring = np.concatenate(loop)
        centre = self._n_grid + i * self._nbk + j
        return np.stack([np.full(len(ring), centre), ring, np.roll(ring, -1)], axis=1)


def _as_quads(tri: np.ndarray, fine: bool) -> np.ndarray:
    """(T, 3) triangles of one block from :meth:`SurfaceMesh._make_piece` -> (Q, 4) quads whose triangles 0 1 2
    and 0 2 3 are the same triangles: a fine block's (grid quads' first triangles, then their second), else
    consecutive pairs sharing corner 0 and an edge (a rectangle's two; a fan's, the last alone when odd)."""
    if fine:
        first, second = np.split(tri, 2)
        return np.concatenate([first, second[:, 2:]], axis=1)           # (v00, v10, v11) + v01
    if len(tri) % 2:
        tri = np.concatenate([tri, tri[-1:, [0, 2, 2]]])                  # degenerate partner: corner 3 = corner 2
    first, second = tri[0::2], tri[1::2]
    return np.concatenate([first, second[:, 2:]], axis=1)
