"""A height map stage of our own: the median of every return in a cell.

graincosim's built-in stage (perception_proc.estimates.heightmap) takes the median of each cell's *lower cluster* of
returns, so that stream returns inside a cell do not lift it; this one is simpler: every return below
``STREAM_ABOVE_RIM_M`` over the rim top counts, and returns standing more than ``STREAM_ABOVE_CELL_M`` above
their cell's median are flagged as the stream (the impact stage fits the stream to those).

Protocol (graincosim ``perception.stages.heightmap``, perception_proc.protocol):
``(ctx: PerceptionContext, inp: PerceptionInput, cart: CartEstimate) -> HeightMap``. ``inp.points`` (N, 3) m
are in the level frame (NaN rows invalid); ``cart.level_from_grid`` (4, 4) maps the cart grid frame (origin at
the front-left inner floor corner, x to the rear, y across, z up) to it. Heights are m above the cart floor on
``ctx.grid`` = (nx, ny) cells, NaN where a cell has no return.
"""
from __future__ import annotations

import numpy as np

from perception_proc.estimates.heightmap import HeightMap
from perception_proc.estimates.rim import CartEstimate
from perception_proc.protocol import PerceptionContext, PerceptionInput

__all__ = ["cell_median", "WALL_CLEAR_M", "STREAM_ABOVE_RIM_M", "STREAM_ABOVE_CELL_M"]

#: returns this close to an inner wall are the wall's, m
WALL_CLEAR_M = 0.05
#: returns higher than this above the rim top are the stream's, the auger's or its tube's, never grain (a cart is
#: filled to below its rim), m
STREAM_ABOVE_RIM_M = 0.2
#: a return this far above its cell's median is the stream's, m
STREAM_ABOVE_CELL_M = 0.3


def cell_median(ctx: PerceptionContext, inp: PerceptionInput, cart: CartEstimate) -> HeightMap:
    """Per-cell median height of the interior returns; see the module docstring."""
    c = ctx.scenario.cart
    nx, ny = ctx.grid
    length, width = c.interior_length_m, c.interior_width_m
    top = c.interior_depth_m + c.rim_height_m
    lfg = cart.level_from_grid
    g = (np.asarray(inp.points, np.float64) - lfg[:3, 3]) @ lfg[:3, :3]      # level -> grid: R^T (p - t)
    with np.errstate(invalid="ignore"):                                     # NaN rows compare False
        inside = ((g[:, 0] > WALL_CLEAR_M) & (g[:, 0] < length - WALL_CLEAR_M) & (g[:, 1] > WALL_CLEAR_M)
                  & (g[:, 1] < width - WALL_CLEAR_M) & (g[:, 2] > -WALL_CLEAR_M)
                  & (g[:, 2] < top + STREAM_ABOVE_RIM_M + 1.0))
    g = g[inside]
    heights = np.full((nx, ny), np.nan, np.float32) if inp.heights_out is None else inp.heights_out
    heights.fill(np.nan)
    counts = np.zeros((nx, ny), np.int32)
    high = g[:, 2] > top + STREAM_ABOVE_RIM_M
    i = np.minimum((g[:, 0] * (nx / length)).astype(np.int64), nx - 1)
    j = np.minimum((g[:, 1] * (ny / width)).astype(np.int64), ny - 1)
    cell = i * ny + j
    low = np.flatnonzero(~high)
    if low.size:
        order = low[np.lexsort((g[low, 2], cell[low]))]
        cs, zs = cell[order], g[order, 2]
        start = np.flatnonzero(np.concatenate(([True], cs[1:] != cs[:-1])))
        cnt = np.diff(np.append(start, cs.size))
        median = 0.5 * (zs[start + (cnt - 1) // 2] + zs[start + cnt // 2])
        heights.reshape(-1)[cs[start]] = median
        counts.reshape(-1)[cs[start]] = cnt
    with np.errstate(invalid="ignore"):
        stream = high | (g[:, 2] > heights.reshape(-1)[cell] + STREAM_ABOVE_CELL_M)
    coverage = float(np.count_nonzero(np.isfinite(heights)) / heights.size)
    return HeightMap(heights, counts, np.asfortranarray(g), stream, coverage)
