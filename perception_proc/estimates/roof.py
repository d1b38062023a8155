"""The cart search's roof test: do points well above the rim cover much of a candidate rectangle?

A tractor cab or a roof over a rim-sized rectangle of points at rim height covers most of it from above; the
auger tube and the grain stream over an open cart cover a thin strip. :func:`roofed` counts the cells of a
:data:`ROOF_CELL_M` raster in the rectangle's own axes that hold a point (:func:`roof_cells`), unless an upper
bound on what the points can cover (:func:`roof_cells_bound`, once per frame) already rules a roof out.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["roofed", "roof_cells", "roof_cells_bound", "ROOF_CELL_M", "MAX_ROOF_FRACTION"]

#: raster cell of the roof test, m
ROOF_CELL_M = 0.20
#: largest share of a candidate rectangle's area covered from above (a tractor cab covers most of its own)
MAX_ROOF_FRACTION = 0.3
#: slack on the cell diagonal in :func:`roof_cells_bound` (far above the rounding of its arithmetic), m
_BOUND_SLACK_M = 1e-3


def roof_cells(above: np.ndarray, centre: np.ndarray, u_long: np.ndarray, long_side: float,
               short_side: float) -> tuple[int, int]:
    """(cells covered, cells in all) of the rectangle's :data:`ROOF_CELL_M` raster (its axes, from one corner)
    by the points ``above`` (2, K) float64 inside it (x and y rows, m, level frame)."""
    d = above - centre[:, None]                                 # (2, K) from the rectangle's centre
    along = d[0] * u_long[0]
    along += d[1] * u_long[1]
    across = d[1] * u_long[0]
    across -= d[0] * u_long[1]
    half_long, half_short = long_side / 2, short_side / 2
    inside = np.flatnonzero((np.abs(along) <= half_long) & (np.abs(across) <= half_short))
    ni, nj = max(1, math.ceil(long_side / ROOF_CELL_M)), max(1, math.ceil(short_side / ROOF_CELL_M))
    if inside.size == 0:
        return 0, ni * nj
    i = np.minimum(((along[inside] + half_long) / ROOF_CELL_M).astype(np.int64), ni - 1)
    j = np.minimum(((across[inside] + half_short) / ROOF_CELL_M).astype(np.int64), nj - 1)
    covered = np.zeros(ni * nj, bool)
    covered[i * nj + j] = True
    return int(np.count_nonzero(covered)), ni * nj


def roof_cells_bound(above: np.ndarray) -> float:
    """The most raster cells of :func:`roof_cells`, for any rectangle, that the points ``above`` (2, K) can
    cover: a covered cell holds one of the points, so it lies within a cell diagonal r of their bounding box,
    and cells do not overlap; so there are at most K of them, and at most the area of the box grown by r
    over a cell's area. The auger tube over the default cart bounds it at ~100 of the ~640 cells of the
    cart's rectangle (a roof needs 30 %), so the roof test itself is rarely needed."""
    k = above.shape[1]
    if k == 0:
        return 0.0
    r = ROOF_CELL_M * math.sqrt(2.0) + _BOUND_SLACK_M
    w, h = float(above[0].max() - above[0].min()), float(above[1].max() - above[1].min())
    return min(float(k), (w + 2 * r) * (h + 2 * r) / ROOF_CELL_M ** 2)


def roofed(above: np.ndarray, centre: np.ndarray, u_long: np.ndarray, long_side: float, short_side: float,
           most_cells: float = math.inf) -> bool:
    """Whether points well above the rim cover more than :data:`MAX_ROOF_FRACTION` of the rectangle's area
    (on a :data:`ROOF_CELL_M` raster): a cab or a roof, not the thin auger tube or stream over an open cart.
    ``above`` (2, K) float64: the points' x and y rows, m, level frame; ``most_cells``: an upper bound on the
    cells they can cover (:func:`roof_cells_bound`): no cell is looked at when it cannot exceed the share."""
    ni, nj = max(1, math.ceil(long_side / ROOF_CELL_M)), max(1, math.ceil(short_side / ROOF_CELL_M))
    if most_cells <= MAX_ROOF_FRACTION * ni * nj:
        return False
    covered, cells = roof_cells(above, centre, u_long, long_side, short_side)
    return covered > MAX_ROOF_FRACTION * cells
