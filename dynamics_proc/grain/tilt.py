"""Grain in a tilted cart: the fill settles to the angle of repose relative to gravity, not to the cart floor.

The height map ``h`` (nx, ny) m stays what it is on flat ground: grain height above the cart floor, along the
floor's normal, cart grid frame (docs/architecture.md). Tilted, a point (x, y, h) of the grid frame stands at
world height ``u = z0 + sx x + sy y + nz h`` (:class:`Tilt`: ``sx``, ``sy`` and ``nz`` are the z components of
the grid axes in the world, the third row of world_from_grid), so every gravity-aware rule is written on ``u``:

* relaxed: every 4-neighbour pair differs in ``u`` by at most tan(repose) * cell (horizontal distances are taken
  as grid distances: off by 1 - cos(tilt), 0.14 % at 3 degrees);
* the cap (:func:`tilted_cap`): grain over a wall top slides off; the highest ``u`` a cell can hold is the
  lowest, over the wall tops w, of ``u_wall(w) + tan(repose) |cell - w|``, in closed form per wall (the wall top
  is a straight segment with ``u_wall`` linear along it: the cone's minimum lies where the slope along the wall
  equals tan(repose) times the cosine of the ray's angle, clipped to the segment). On the low side the cap is
  lower: that is where a full cart spills;
* deposit (:func:`deposit_tilted`): the flat-topped heap law of dynamics_proc.grain.fill on ``u``, the volume
  ``sum(dh) * cell^2`` exact;
* a change of tilt (:func:`settle`): grain above the new cap spills; grain steeper than the repose slides: the
  highest relaxed surface under ``u`` (the min-plus envelope with the 4-neighbour slope, exact, two cumulative
  minima per axis: :func:`l1_envelope`) keeps what stays, and the volume that slid fills the lowest cells level
  (a lake fill, which stays relaxed), then the cap clips again. Volume is conserved: delivered = in cart +
  spilled, to round-off.

Level (no tilt) the flat-ground functions of dynamics_proc.grain.fill are used unchanged.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dynamics_proc.grain.fill import GrainGrid, _heap_height

__all__ = ["Tilt", "tilt_of", "tilted_cap", "l1_envelope", "deposit_tilted", "settle"]


@dataclass(frozen=True)
class Tilt:
    """How the cart grid frame stands in the world: the world height of grid point (x, y, h) is
    ``sx x + sy y + nz h`` plus a constant (m)."""

    sx: float
    sy: float
    nz: float

    def floor(self, grid: GrainGrid) -> np.ndarray:
        """World height of the floor under each cell centre relative to the grid origin, (nx, ny) m."""
        x, y = grid.centres()
        return self.sx * x[:, None] + self.sy * y[None, :]


def tilt_of(world_from_grid: np.ndarray) -> Tilt | None:
    """The :class:`Tilt` of a world_from_grid (4, 4) pose, None when its z axis is vertical (level)."""
    r = world_from_grid[2, :3]
    if r[0] == 0.0 and r[1] == 0.0:
        return None
    return Tilt(float(r[0]), float(r[1]), float(r[2]))


def _wall_cone_min(px: np.ndarray, py: np.ndarray, p0: tuple[float, float], d: tuple[float, float], length: float,
                   u0: float, k: float, tan_r: float) -> np.ndarray:
    """min over t in [0, length] of ``u0 + k t + tan_r |P - (p0 + t d)|`` for points P = (px, py), d unit."""
    rx, ry = px - p0[0], py - p0[1]
    along = rx * d[0] + ry * d[1]
    across = np.abs(rx * d[1] - ry * d[0])
    t = np.clip(along - across * k / math.sqrt(tan_r * tan_r - k * k), 0.0, length)
    return u0 + k * t + tan_r * np.hypot(along - t, across)


def tilted_cap(grid: GrainGrid, tilt: Tilt) -> np.ndarray:
    """Highest grain height above the floor (nx, ny) m each cell can hold before it slides over a wall top, in
    the tilted cart (the module docstring). Needs the floor's slope below tan(repose)."""
    x, y = grid.centres()
    px, py = np.broadcast_arrays(x[:, None], y[None, :])
    length, width, t = grid.length_m, grid.width_m, grid.tan_repose
    if max(abs(tilt.sx), abs(tilt.sy)) >= t:
        raise ValueError(f"the cart floor's slope ({max(abs(tilt.sx), abs(tilt.sy)):.2f}) reaches the angle of "
                         f"repose ({t:.2f}): the grain would not stay in the cart")
    top = tilt.nz * grid.depth_m                         # the wall tops' height above the floor, world z
    walls = (((0.0, 0.0), (1.0, 0.0), length, tilt.sx), ((0.0, width), (1.0, 0.0), length, tilt.sx),
             ((0.0, 0.0), (0.0, 1.0), width, tilt.sy), ((length, 0.0), (0.0, 1.0), width, tilt.sy))
    u = np.minimum.reduce([_wall_cone_min(px, py, p0, d, n, top + tilt.sx * p0[0] + tilt.sy * p0[1], k, t)
                           for p0, d, n, k in walls])
    return (u - tilt.floor(grid)) / tilt.nz


def l1_envelope(u: np.ndarray, step: float) -> np.ndarray:
    """The highest surface (nx, ny) under ``u`` whose 4-neighbour differences are at most ``step``: the min-plus
    convolution with ``step * (|di| + |dj|)``, separable, each axis by a forward and a backward cumulative
    minimum (exact up to the rounding of adding and removing the ramp)."""
    out = u
    for axis in (0, 1):
        n = out.shape[axis]
        ramp = step * np.arange(n, dtype=np.float64)
        ramp = ramp[:, None] if axis == 0 else ramp[None, :]
        fwd = np.minimum.accumulate(out - ramp, axis=axis) + ramp
        rev = np.flip(np.minimum.accumulate(np.flip(out + ramp, axis=axis), axis=axis), axis=axis) - ramp
        out = np.minimum(fwd, rev)
    return out


def deposit_tilted(h: np.ndarray, gx: float, gy: float, vol_m3: float, grid: GrainGrid, tilt: Tilt,
                   cap: np.ndarray) -> tuple[np.ndarray, float]:
    """:func:`dynamics_proc.grain.fill.deposit` in the tilted cart: the heap ``max(u, H - tan(repose) max(r - r0,
    0))`` around the impact (gx, gy) (grid frame, m) on the world heights ``u``, H exact for the volume; then the
    ``cap`` (nx, ny) m (:func:`tilted_cap`) clips what slides over a wall top. Returns (heights (nx, ny) m,
    spilled m^3)."""
    if vol_m3 <= 0.0:
        return h, 0.0
    x, y = grid.centres()
    floor = tilt.floor(grid)
    u = floor + tilt.nz * h
    r = np.hypot(x[:, None] - gx, y[None, :] - gy)
    base = -grid.tan_repose * np.maximum(r - grid.flat_radius_m, 0.0)
    hh = _heap_height((u - base).ravel(), vol_m3 * tilt.nz / grid.cell_area_m2)
    heap = (np.maximum(u, hh + base) - floor) / tilt.nz
    new = np.minimum(heap, cap)
    return new, float(np.sum(heap - new)) * grid.cell_area_m2


def settle(h: np.ndarray, grid: GrainGrid, tilt: Tilt, cap: np.ndarray) -> tuple[np.ndarray, float]:
    """Settle ``h`` (nx, ny) m, relaxed for an earlier tilt, in the cart tilted by ``tilt`` with its ``cap``
    (:func:`tilted_cap`): spill over the new cap, slide to the repose slope, the slid volume levelled into the
    lowest cells, the cap again. Returns (heights (nx, ny) m, spilled m^3)."""
    floor = tilt.floor(grid)
    over = np.maximum(h - cap, 0.0)
    kept = h - over
    u = floor + tilt.nz * kept
    v = l1_envelope(u, grid.tan_repose * grid.cell_m)
    slid = float(np.sum(u - v))
    if slid > 0.0:
        level = _heap_height(v.ravel(), slid)
        v = np.maximum(v, level)
    new = np.maximum((v - floor) / tilt.nz, 0.0)
    clipped = np.minimum(new, cap)
    spill = (float(np.sum(over)) + float(np.sum(new - clipped))) * grid.cell_area_m2
    return clipped, spill
