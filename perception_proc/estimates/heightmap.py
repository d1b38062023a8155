"""Grain height map on the controller's grid from LiDAR points and the perceived cart pose.

Points go from the level frame to the cart grid frame through the perceived pose (``CartEstimate``); the
height above the floor is z in that frame. Points within :data:`WALL_CLEAR_M` (plus 3 sigma of range noise) of
an inner wall are dropped: they may lie on the wall, not on the grain, given the pose error. A depth camera's
error grows with the square of its depth and lies along its ray, so each of its points takes 3 sigma of its own
error's component across the wall (``wall_sigma_xy``): a far wall's face seen head-on, whose noisy points reach
tens of cm into the cart at a few metres, no longer reads as grain at the wall's height, while a camera looking
down keeps the cells beside the walls.

Per cell the statistic is the *median of the lower cluster*: the median of the returns within
:data:`CLUSTER_GAP_M` of the cell's lowest return. Why: the grain surface is single-valued, and the only
returns above it in a cell are the falling stream's (and spill in the air). The maximum or the plain median
would count them as grain; the bare minimum is biased low by range noise (by about 1-2 sigma for a handful of
returns). The median of the lowest cluster rejects the stream and averages the noise. With range noise of
sigma the cluster reaches :data:`CLUSTER_GAP_M` plus :data:`CLUSTER_NOISE_SIGMAS` sigma above the lowest
return: a fixed gap would cut the upper tail of the noise and bias the median low (by about 1 cm at
sigma = 5 cm, which the controller turns into overfill). The stream-return threshold widens likewise.

A cell whose only returns are the stream's (the stream hides the pile beneath it) has no lower cluster on the
grain; it is found as a cell standing more than :data:`STREAM_STEP_M` above the lower quartile of its
neighbourhood (:data:`NEIGHBOURHOOD` cells square; a grain pile at the angle of repose cannot rise that fast;
the quartile, not the median, because an occluding strip such as the auger tube can fill half the window)
and is left NaN: no answer rather than the stream's (or the tube's) height. Returns more than
:data:`STREAM_MIN_HEIGHT_M` above their cell's surface, above any heap (:data:`HEAP_MAX_M` over the rim), or in
such cells, are returned as stream returns for the impact search; the pipeline then blanks the cells the
stream hides (``impact.blank_under_stream``).
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from cosim.scenario.config import Cart

__all__ = ["HeightMap", "height_map", "grid_shape", "WALL_CLEAR_M", "CLUSTER_GAP_M", "CLUSTER_NOISE_SIGMAS",
           "STREAM_STEP_M",
           "STREAM_MIN_HEIGHT_M", "HEAP_MAX_M", "STREAM_TOP_M"]

#: returns closer than this to an inner wall are taken as wall returns, m: it must exceed the error of the
#: perceived cart pose (a few cm, more when an end of the cart is out of view), or the inner wall faces
#: read as grain at the wall's height in the border cells
WALL_CLEAR_M = 0.08
#: returns within this of a cell's lowest return form its lower cluster, m
CLUSTER_GAP_M = 0.10
#: the lower cluster also spans this many sigmas of range noise (the lowest of a handful of returns lies up to
#: about 2 sigma below the surface, the highest as far above it)
CLUSTER_NOISE_SIGMAS = 4.0
#: a cell more than this above its neighbourhood median holds only stream returns, m
STREAM_STEP_M = 0.35
#: a return more than this above its cell's grain surface is a stream return, m
STREAM_MIN_HEIGHT_M = 0.15
#: span of the z sort key per cell, m (more than any grid-frame height kept)
Z_SPAN_M = 16.0
#: percentile of the neighbourhood heights the stream-cell test compares with (low: an occluding strip such
#: as the auger tube may fill half the window)
NEIGHBOUR_PERCENTILE = 25.0
#: side of the square neighbourhood used for the stream-cell test, cells (odd)
NEIGHBOURHOOD = 7
_NEIGHBOURHOOD_KERNEL = np.ones((NEIGHBOURHOOD, NEIGHBOURHOOD), np.uint8)
#: grain can heap at most this far above the rim top (a 3 m wide cart at 23-25 deg repose heaps ~0.7 m), m
HEAP_MAX_M = 0.8
#: stream returns are looked for up to this far above the rim top; the auger tube lies higher, m
STREAM_TOP_M = 1.2


@dataclass(frozen=True)
class HeightMap:
    """``heights`` (nx, ny) float32 m above the cart floor, NaN where no answer; ``counts`` (nx, ny) int32
    returns per cell; ``grid_points`` (M, 3) float64 interior points in the grid frame (column-major); ``stream`` (M,) bool
    which of them are stream returns; ``coverage`` fraction of cells with a height."""

    heights: np.ndarray
    counts: np.ndarray
    grid_points: np.ndarray
    stream: np.ndarray
    coverage: float


#: np.take mode for indices that lie in range by construction (from np.flatnonzero, an argsort, a cell index):
#: numpy's wrapping gather skips the per-index bounds check of the default (the same values, ~25 % fewer
#: instructions than a[idx])
_IN_RANGE = "wrap"


def _gather(a: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """``a[idx]`` for a 1-D ``a`` and int64 indices ``idx`` known to lie in range."""
    return np.take(a, idx, mode=_IN_RANGE)


def _interior_points(p: np.ndarray, level_from_grid: np.ndarray, z_lo: float, z_hi: float,
                     xy_box: tuple[float, float, float, float], index: bool = False):
    """Level-frame points (N, 3) into the grid frame, R^T (p - t), keeping those with grid z in (z_lo, z_hi)
    and grid x, y strictly inside ``xy_box`` (x_lo, x_hi, y_lo, y_hi), m. Returns (3, M) float64 C-contiguous
    coordinate rows in the order of ``p``; NaN rows never pass. With ``index``, also the rows of ``p`` kept
    (M,) int64.

    Written out per component on contiguous coordinate rows (a 3 x 3 BLAS product on tall arrays is slower
    than nine multiply-adds). When the grid's z axis is the level frame's (a cart pose is a yaw: the third row
    and column of R are exactly (0, 0, 1)), grid z is level z - t_z and x, y have no z term (the dropped
    terms are exact zeros: the same numbers), and every coordinate is computed for every point, then one
    selection: full-length arithmetic costs far less per point than gathering subsets. Otherwise z first, and
    x and y for the points in the slab only."""
    r, t = level_from_grid[:3, :3], level_from_grid[:3, 3]
    x_lo, x_hi, y_lo, y_hi = xy_box
    upright = bool(r[0, 2] == 0.0 and r[1, 2] == 0.0 and r[2, 2] == 1.0 and r[2, 0] == 0.0 and r[2, 1] == 0.0)
    with np.errstate(invalid="ignore"):
        if upright:
            dx, dy = p[:, 0] - t[0], p[:, 1] - t[1]
            rows = np.empty((3, p.shape[0]))
            gx, gy, gz = rows
            np.multiply(dx, r[0, 0], out=gx)
            gx += r[1, 0] * dy
            np.multiply(dx, r[0, 1], out=gy)
            gy += r[1, 1] * dy
            np.subtract(p[:, 2], t[2], out=gz)
            keep = np.flatnonzero((gz > z_lo) & (gz < z_hi) & (gx > x_lo) & (gx < x_hi) & (gy > y_lo) & (gy < y_hi))
            out = np.take(rows, keep, axis=1, mode=_IN_RANGE)
            return (out, keep) if index else out
        gz = r[0, 2] * (p[:, 0] - t[0]) + r[1, 2] * (p[:, 1] - t[1]) + r[2, 2] * (p[:, 2] - t[2])
        sel = np.flatnonzero((gz > z_lo) & (gz < z_hi))
        x, y, z = (p[:, k][sel] - t[k] for k in range(3))
        gx = r[0, 0] * x + r[1, 0] * y + r[2, 0] * z
        gy = r[0, 1] * x + r[1, 1] * y + r[2, 1] * z
        inside = (gx > x_lo) & (gx < x_hi) & (gy > y_lo) & (gy < y_hi)
        out = np.stack([gx[inside], gy[inside], gz[sel][inside]])
        return (out, sel[inside]) if index else out


def _lower_quartile(heights: np.ndarray, cells: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """Per cell, the :data:`NEIGHBOUR_PERCENTILE` of the finite heights in its :data:`NEIGHBOURHOOD` square
    (nearest-rank on the sorted window; NaN where the window is empty). (nx, ny) float32; with ``cells``
    (row indices, column indices) only at those cells, (K,) float32."""
    half = NEIGHBOURHOOD // 2
    pad = np.pad(heights, half, constant_values=np.nan)
    win = sliding_window_view(pad, (NEIGHBOURHOOD, NEIGHBOURHOOD))
    win = win.reshape(*heights.shape, -1) if cells is None else win[cells].reshape(cells[0].size, -1)
    win = np.sort(win, axis=-1)
    k = np.count_nonzero(np.isfinite(win), axis=-1)            # NaN sorts last: finite values come first
    idx = np.maximum(np.floor(NEIGHBOUR_PERCENTILE / 100.0 * (k - 1)).astype(np.int64), 0)
    q = np.take_along_axis(win, idx[..., None], axis=-1)[..., 0]
    return np.where(k > 0, q, np.nan)


def _stream_cells(heights: np.ndarray) -> np.ndarray:
    """(nx, ny) bool: cells more than :data:`STREAM_STEP_M` above the lower quartile of their neighbourhood.

    The neighbourhood minimum (OpenCV erosion, NaN as +inf) never exceeds the quartile, so only cells more than
    the step above their minimum (a handful: the stream, steep edges) need the sorted window."""
    finite = np.isfinite(heights)
    h = np.where(finite, heights, np.float32(np.inf))           # float32, as the heights
    low = cv2.erode(h, _NEIGHBOURHOOD_KERNEL)                   # border ignored (+inf)
    out = np.zeros(heights.shape, bool)
    # (rows, columns) from flat indices: np.nonzero on a 2-D mask costs several times more
    cand = np.divmod(np.flatnonzero(finite & (heights > low + np.float32(STREAM_STEP_M))), heights.shape[1])
    if cand[0].size:
        out[cand] = heights[cand] > _lower_quartile(heights, cand) + STREAM_STEP_M
    return out


def _cell_index(gx: np.ndarray, gy: np.ndarray, per_m_x: float, per_m_y: float,
                shape: tuple[int, int]) -> np.ndarray:
    """Flat grid cell ``i * ny + j`` (M,) float64 (whole numbers, exact) of grid-frame points ``gx``, ``gy`` (M,)
    m, at ``per_m_x``, ``per_m_y`` cells per m, each index truncated and clipped to the last cell of ``shape``
    (nx, ny): the numbers of ``np.minimum((gx * per_m_x).astype(np.int64), nx - 1)`` and its y twin, in float64
    (truncation, clipping and the small products are exact there), so that the cell serves the sort key
    as it is and takes one cast to int64 (numpy's int64 minimum has no vector loop)."""
    nx, ny = shape
    i = np.trunc(gx * per_m_x)
    np.minimum(i, nx - 1, out=i)
    j = np.trunc(gy * per_m_y)
    np.minimum(j, ny - 1, out=j)
    i *= ny
    i += j
    return i


def grid_shape(cart: Cart, cell_m: float) -> tuple[int, int]:
    """(nx, ny) cells of a grid of ``cell_m`` over the cart interior (:meth:`Cart.grid_shape`)."""
    return cart.grid_shape(cell_m)


def height_map(points_level: np.ndarray, level_from_grid: np.ndarray, cart: Cart, cell_m: float,
               min_points: int = 1, noise_sigma_m: float = 0.0, out: np.ndarray | None = None,
               wall_sigma_xy: np.ndarray | None = None) -> HeightMap:
    """Height map from level-frame points (N, 3) float (NaN rows invalid) and the perceived 4 x 4 pose.

    ``out``: optional (nx, ny) float32 destination for the heights (filled and returned inside the result).
    ``wall_sigma_xy``: optional (N, 2) m, each point's 1-sigma position error along grid x and y
    (:func:`perception_proc.estimates.pointsigma.wall_sigma_xy`); a point is then kept only
    :data:`WALL_CLEAR_M` plus 3 of these inside each wall. Without it every point keeps 3 ``noise_sigma_m``.
    """
    nx, ny = grid_shape(cart, cell_m)
    L, W = cart.interior_length_m, cart.interior_width_m
    p = np.asarray(points_level, dtype=np.float64)              # invalid beams are whole NaN rows
    clear = WALL_CLEAR_M + 3.0 * noise_sigma_m
    top = cart.interior_depth_m + cart.rim_height_m
    if wall_sigma_xy is None:
        g = _interior_points(p, level_from_grid, -clear, top + STREAM_TOP_M, (clear, L - clear, clear, W - clear))
    else:
        c = WALL_CLEAR_M
        g, kept = _interior_points(p, level_from_grid, -clear, top + STREAM_TOP_M, (c, L - c, c, W - c), index=True)
        s = 3.0 * np.asarray(wall_sigma_xy, np.float64)[kept]
        with np.errstate(invalid="ignore"):
            inside = ((g[0] > c + s[:, 0]) & (g[0] < L - c - s[:, 0]) & (g[1] > c + s[:, 1])
                      & (g[1] < W - c - s[:, 1]))
        g = np.ascontiguousarray(g[:, inside])
    gx, gy, gz = g                                              # contiguous rows of the interior points
    g = g.T                                                     # column-major (M, 3): coordinates contiguous
    high = gz > top + HEAP_MAX_M                                # above any heap: stream (or spill) only
    heights = np.full((nx, ny), np.nan, np.float32) if out is None else out
    heights.fill(np.nan)
    counts = np.zeros((nx, ny), np.int32)
    if g.shape[0] == 0:
        return HeightMap(heights, counts, g, np.zeros(0, bool), 0.0)
    cell_f = _cell_index(gx, gy, nx / L, ny / W, (nx, ny))
    cell = cell_f.astype(np.int64)
    low = np.flatnonzero(~high)
    # one sort by (cell, z): z lies in (-1, top + HEAP_MAX) < Z_SPAN_M, so cell * Z_SPAN_M + z + 1 orders both.
    # Stable (numpy: timsort, which takes ordered runs as they come): the points arrive scan line by scan
    # line, so the keys hold ordered runs. The keys are positive floats, whose IEEE bit patterns read as
    # int64 order the same way and compare faster (no NaN rule): the same order at about half the cost of
    # the default quicksort on the floats
    key = cell_f * Z_SPAN_M + (gz + 1.0)
    order = _gather(low, np.argsort(_gather(key, low).view(np.int64), kind="stable"))
    cs, zs = _gather(cell, order), _gather(gz, order)
    if cs.size == 0:
        return HeightMap(heights, counts, g, high.copy(), 0.0)
    start = np.flatnonzero(np.concatenate(([True], cs[1:] != cs[:-1])))
    cnt = np.diff(start, append=cs.size)                        # returns below any heap per occupied cell
    uniq = cs[start]
    zmin = zs[start]
    lower = zs <= np.repeat(zmin, cnt) + (CLUSTER_GAP_M + CLUSTER_NOISE_SIGMAS * noise_sigma_m)
    k = np.add.reduceat(lower, start, dtype=np.int64)           # lower cluster is a prefix of each cell
    med = 0.5 * (zs[start + (k - 1) // 2] + zs[start + k // 2])
    enough = k >= min_points
    flat = heights.reshape(-1)
    flat[uniq[enough]] = med[enough]
    counts.reshape(-1)[uniq] = cnt
    # cells holding only stream returns stand far above their neighbourhood
    stream_cell = _stream_cells(heights)
    heights[stream_cell] = np.nan
    # per cell, the height above which a return is the stream's (float32, as the heights): -inf in a stream
    # cell (all its returns are), NaN in an empty one (none is); one lookup per return
    above = heights + np.float32(STREAM_MIN_HEIGHT_M + CLUSTER_NOISE_SIGMAS * noise_sigma_m)
    above[stream_cell] = -np.inf
    with np.errstate(invalid="ignore"):
        stream = high | (gz > _gather(above.reshape(-1), cell))
    coverage = float(np.count_nonzero(np.isfinite(heights)) / heights.size)
    return HeightMap(heights, counts, g, stream, coverage)
