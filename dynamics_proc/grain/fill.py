"""Grain fill model: a height map over the cart floor, deposit, repose relaxation, wall spill.

Height map ``h`` (nx, ny) float64, m above the cart floor, cart grid frame (x from the front inner wall to the
rear, y from the left inner wall across), cell (i, j) centred at ((i + 0.5) c, (j + 0.5) c), c = ``cell_m``.
"Relaxed" means every 4-neighbour pair differs by at most tan(repose) * c.

Walls bound the pile (no flow through them). Grain above the wall top slides over it: a cell may stand at
most ``depth + tan(repose) * d_wall`` high, d_wall the distance from its centre to the nearest inner wall
(the heap may rise from the wall top at the angle of repose). That cap is itself relaxed, so clipping to it
keeps a relaxed map relaxed; what it clips is spill.

Deposit (:func:`deposit`): grain from a point source onto a relaxed surface settles as the heap
``max(h, H - tan(repose) * max(r - r0, 0))`` (a cone with a flat top of radius r0 over the impact point, r
the distance from it), H solved exactly so that the added volume is the delivered one (Newton on a convex
piecewise-linear function, solved exactly by sorting). Both parts are relaxed, so the result is; it is
unconditionally stable for any volume. :func:`relax` relaxes an arbitrary map by volume-conserving pairwise
exchange (used for initial conditions and as an independent check).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from cosim.scenario.config import Scenario

__all__ = ["GRID_TOLERANCE", "GrainGrid", "initial_heights", "deposit", "relax", "max_slope", "volume",
           "section_rows", "resample"]

#: relative tolerance when checking that the cell divides the cart interior
GRID_TOLERANCE = 1e-9
#: pairwise exchange factor per neighbour pair (<= 1/4 keeps heights non-negative with 4 neighbours)
EXCHANGE_FACTOR = 0.25
#: grids whose cell centres and caps are kept (a run has two: the grain grid and the controller's)
GRID_CACHE = 8


def _cells(extent_m: float, cell_m: float, what: str) -> int:
    n = round(extent_m / cell_m)
    if n < 1 or abs(extent_m / cell_m - n) > GRID_TOLERANCE * max(1.0, n):
        raise ValueError(f"grain.cell_m = {cell_m} m does not divide the cart interior {what} {extent_m} m; "
                         f"choose a cell that divides it (e.g. {extent_m / max(1, n):g} m)")
    return n


@dataclass(frozen=True)
class GrainGrid:
    """Geometry of the height map: cells, cart interior, wall top, angle of repose."""

    nx: int
    ny: int
    cell_m: float
    depth_m: float
    tan_repose: float
    flat_radius_m: float

    @classmethod
    def from_scenario(cls, s: Scenario) -> "GrainGrid":
        c = s.grain.cell_m
        return cls(_cells(s.cart.interior_length_m, c, "length"), _cells(s.cart.interior_width_m, c, "width"),
                   c, s.cart.interior_depth_m, math.tan(s.crop.repose_rad), s.grain.deposit_radius_m)

    @property
    def length_m(self) -> float:
        return self.nx * self.cell_m

    @property
    def width_m(self) -> float:
        return self.ny * self.cell_m

    @property
    def cell_area_m2(self) -> float:
        return self.cell_m * self.cell_m

    def centres(self) -> tuple[np.ndarray, np.ndarray]:
        """Cell-centre coordinates (x (nx,), y (ny,)) float64, m, cart grid frame."""
        return (np.arange(self.nx) + 0.5) * self.cell_m, (np.arange(self.ny) + 0.5) * self.cell_m

    def cap(self) -> np.ndarray:
        """Highest grain each cell can hold before it slides over a wall top, (nx, ny) float64 m."""
        x, y = self.centres()
        dx = np.minimum(x, self.length_m - x)[:, None]
        dy = np.minimum(y, self.width_m - y)[None, :]
        return self.depth_m + self.tan_repose * np.minimum(dx, dy)


def initial_heights(grid: GrainGrid, fill_m: float) -> np.ndarray:
    """Flat initial fill ``fill_m`` m (clipped to the cap, so an overfull start is a full heap), (nx, ny)."""
    return np.minimum(np.full((grid.nx, grid.ny), float(fill_m)), grid.cap())


def volume(h: np.ndarray, grid: GrainGrid) -> float:
    """Grain volume in the map, m^3 (float64 sum)."""
    return float(np.sum(h, dtype=np.float64)) * grid.cell_area_m2


def deposit(h: np.ndarray, gx: float, gy: float, vol_m3: float, grid: GrainGrid,
            cap: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """Deposit ``vol_m3`` around the impact point (gx, gy) (cart grid frame, m) onto relaxed ``h``.

    Returns (new heights (nx, ny) float64, spilled volume m^3 that slid over a wall top). The impact point
    must lie in the interior (the caller classifies impacts elsewhere as spill). Volume is conserved:
    volume(new) - volume(h) + spilled == vol_m3 to round-off.
    """
    if vol_m3 <= 0.0:
        return h, 0.0
    cap = _cap(grid) if cap is None else cap
    x, y = _centres(grid)
    r = np.hypot(x[:, None] - gx, y[None, :] - gy)
    base = -grid.tan_repose * np.maximum(r - grid.flat_radius_m, 0.0)   # heap shape, apex 0
    gap = h - base                                                        # heap height H at which a cell joins
    hh = _heap_height(gap.ravel(), vol_m3 / grid.cell_area_m2)
    heap = np.maximum(h, hh + base)
    new = np.minimum(heap, cap)
    spilled = float(np.sum(heap - new)) * grid.cell_area_m2
    return new, spilled


@lru_cache(maxsize=GRID_CACHE)
def _centres(grid: GrainGrid) -> tuple[np.ndarray, np.ndarray]:
    """:meth:`GrainGrid.centres`, computed once per grid (read-only)."""
    return tuple(_read_only(a) for a in grid.centres())


@lru_cache(maxsize=GRID_CACHE)
def _cap(grid: GrainGrid) -> np.ndarray:
    """:meth:`GrainGrid.cap`, computed once per grid (read-only)."""
    return _read_only(grid.cap())


def _read_only(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


def _heap_height(gap: np.ndarray, target: float) -> float:
    """H with sum(max(H - gap, 0)) == target (> 0): exact, by sorting the candidate cells. gap (n,) m."""
    g0 = float(gap.min())
    # H <= g0 + target, so no other cell can join. The candidates hold neither NaN nor -0.0 (gap = h - base with
    # base <= -0.0), so every sort orders them alike: the stable one is twice as fast here as the default
    cand = np.sort(gap[gap < g0 + target], kind="stable")
    if cand.size == 0:                  # target below the resolution of g0 (g0 + target == g0): one cell, exact
        return g0 + target
    k = np.arange(1, cand.size + 1)
    csum = np.cumsum(cand)
    # V at H = cand[k-1] with the first k-1 cells active; find the last breakpoint with V <= target
    v_at = k * cand - csum
    j = int(np.searchsorted(v_at, target, side="right"))     # cells 0..j-1 active at the solution
    return float((target + csum[j - 1]) / j)


def relax(h: np.ndarray, grid: GrainGrid, tol_slope: float = 1e-4, max_iter: int = 200_000,
          cap: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """Relax an arbitrary non-negative map to the angle of repose, conserving volume; walls bound it.

    Pairwise exchange: each 4-neighbour pair steeper than tan(repose) moves EXCHANGE_FACTOR of its excess
    difference from the high cell to the low one (all pairs at once), then wall cells above the cap lose the
    excess as spill (the cap of inner cells follows from the slopes). Iterates until every pair is within
    ``tol_slope`` (dimensionless) of tan(repose). Returns
    (relaxed heights (nx, ny) float64, spilled m^3). Raises RuntimeError if it does not converge.
    """
    cap = grid.cap() if cap is None else cap
    edge = np.zeros(cap.shape, bool)                     # grain leaves over a wall top from the wall cells only
    edge[[0, -1], :] = True
    edge[:, [0, -1]] = True
    cap = np.where(edge, cap, np.inf)
    h = np.array(h, dtype=np.float64)
    if np.any(h < 0.0) or not np.all(np.isfinite(h)):
        raise ValueError("heights must be finite and non-negative")
    s = grid.tan_repose * grid.cell_m
    tol = tol_slope * grid.cell_m
    v0 = float(np.sum(h))
    over = np.maximum(h - cap, 0.0)
    h -= over
    for _ in range(max_iter):
        dx = h[1:, :] - h[:-1, :]
        dy = h[:, 1:] - h[:, :-1]
        ex = np.sign(dx) * np.maximum(np.abs(dx) - s, 0.0)
        ey = np.sign(dy) * np.maximum(np.abs(dy) - s, 0.0)
        worst = max(float(np.abs(ex).max(initial=0.0)), float(np.abs(ey).max(initial=0.0)))
        if worst <= tol:
            break
        fx, fy = EXCHANGE_FACTOR * ex, EXCHANGE_FACTOR * ey
        h[1:, :] -= fx
        h[:-1, :] += fx
        h[:, 1:] -= fy
        h[:, :-1] += fy
        np.maximum(h, 0.0, out=h)       # guards round-off only (the factor keeps heights >= 0)
        np.minimum(h, cap, out=h)
    else:
        raise RuntimeError(f"relax did not converge in {max_iter} iterations (worst excess {worst:g} m)")
    spilled = (v0 - float(np.sum(h))) * grid.cell_area_m2
    return h, spilled


def max_slope(h: np.ndarray, cell_m: float) -> float:
    """Largest |difference| / cell over all 4-neighbour pairs (dimensionless; tan of the steepest angle)."""
    m = 0.0
    if h.shape[0] > 1:
        m = max(m, float(np.abs(np.diff(h, axis=0)).max()))
    if h.shape[1] > 1:
        m = max(m, float(np.abs(np.diff(h, axis=1)).max()))
    return m / cell_m


def section_rows(nx: int, cell_m: float, length_m: float, sections: int) -> np.ndarray:
    """Section index (0-based, front to back) of each row of cells along x, (nx,) int64."""
    x = (np.arange(nx) + 0.5) * cell_m
    return np.minimum((x / (length_m / sections)).astype(np.int64), sections - 1)


def resample(h: np.ndarray, cell_src_m: float, cell_dst_m: float, length_m: float, width_m: float) -> np.ndarray:
    """Area resample of a height map onto a grid of ``cell_dst_m`` cells: mean of the source cells whose
    centres fall in each destination cell (NaN where none do). (nx_src, ny_src) -> (nx_dst, ny_dst) float64."""
    if abs(cell_src_m - cell_dst_m) <= GRID_TOLERANCE * cell_dst_m:
        return np.array(h, dtype=np.float64)
    nxd, nyd = max(1, round(length_m / cell_dst_m)), max(1, round(width_m / cell_dst_m))
    xs = (np.arange(h.shape[0]) + 0.5) * cell_src_m
    ys = (np.arange(h.shape[1]) + 0.5) * cell_src_m
    ix = np.minimum((xs / cell_dst_m).astype(np.int64), nxd - 1)
    iy = np.minimum((ys / cell_dst_m).astype(np.int64), nyd - 1)
    flat = (ix[:, None] * nyd + iy[None, :]).ravel()
    sums = np.bincount(flat, weights=np.asarray(h, dtype=np.float64).ravel(), minlength=nxd * nyd)
    counts = np.bincount(flat, minlength=nxd * nyd)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = sums / counts
    return out.reshape(nxd, nyd)
