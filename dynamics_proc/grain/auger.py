"""Unloading auger: spout pose, flow with spool-up / run-out, the ballistic stream and its first surface.

Spout (combine body frame): pivot + length * (cos e cos s, cos e sin s, sin e), s = swing (from +x towards
+y), e = elevation. Grain leaves the spout at ``exit_speed_mps`` relative to the combine, horizontally along
the swing direction and ``exit_down_deg`` below the horizontal. A particle released s seconds ago sits at
spout + v_exit s + g s^2 / 2 in a frame moving with the combine: that parabola is the stream's instantaneous
shape, and where it first meets a surface at the cart's current pose is where grain lands now.

Surfaces, in the cart grid frame (z up from the floor): inside the interior the grain surface h(x, y) (the
floor where h = 0); a band ``max(wall_thickness, rim_width)`` wide around the interior at the rim top; the
ground at z = -floor_height beyond. Impacts on the band or the ground are spill.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from cosim.scenario.config import Scenario

__all__ = ["GRAVITY_MPS2", "STREAM_ROWS", "SURFACE_NONE", "SURFACE_GRAIN", "SURFACE_WALL", "SURFACE_GROUND",
           "AugerParams", "spout_world", "exit_velocity_world", "flow_advance", "Impact", "first_surface",
           "stream_rows", "landing_point", "landing_xy"]

GRAVITY_MPS2 = 9.80665
#: rows of the ``stream`` block (CONTRACTS.md)
STREAM_ROWS = 64
#: coarse samples along the parabola, then two refinements of the crossing interval with this many each
_COARSE, _FINE = 48, 48
SURFACE_NONE, SURFACE_GRAIN, SURFACE_WALL, SURFACE_GROUND = 0, 1, 2, 3
#: ramps shorter than this are instantaneous (avoids overflowing 1 / ramp), s
MIN_RAMP_S = 1e-9


@dataclass(frozen=True)
class AugerParams:
    """Auger geometry (combine body frame, m, rad), flow (m^3/s) and the cart surfaces the stream can hit."""

    pivot: tuple[float, float, float]
    arm: tuple[float, float, float]          # pivot -> spout, combine body frame, m
    exit_dir: tuple[float, float, float]     # unit exit direction, combine body frame
    exit_speed_mps: float
    flow_m3ps: float
    spool_up_s: float
    run_out_s: float
    stream_radius_m: float
    length_m: float                          # cart interior, m
    width_m: float
    band_m: float                            # wall / rim band width around the interior, m
    rim_top_m: float                         # rim top above the floor, m
    floor_height_m: float                    # floor above the ground, m

    @classmethod
    def from_scenario(cls, s: Scenario) -> "AugerParams":
        a, c = s.auger, s.cart
        sw, el, dn = math.radians(a.swing_deg), math.radians(a.elevation_deg), math.radians(a.exit_down_deg)
        arm = (a.length_m * math.cos(el) * math.cos(sw), a.length_m * math.cos(el) * math.sin(sw),
               a.length_m * math.sin(el))
        ed = (math.cos(dn) * math.cos(sw), math.cos(dn) * math.sin(sw), -math.sin(dn))
        return cls(tuple(a.pivot_xyz_m), arm, ed, a.exit_speed_mps, a.flow_m3ps, a.spool_up_s, a.run_out_s,
                   a.stream_radius_m, c.interior_length_m, c.interior_width_m,
                   max(c.wall_thickness_m, c.rim_width_m), c.interior_depth_m + c.rim_height_m, c.floor_height_m)


def spout_world(cx: float, cy: float, cyaw: float, a: AugerParams) -> np.ndarray:
    """Spout position (3,) float64, world m, for the combine body pose (cx m, cy m, cyaw rad)."""
    bx, by, bz = (a.pivot[i] + a.arm[i] for i in range(3))
    c, s = math.cos(cyaw), math.sin(cyaw)
    return np.array([cx + c * bx - s * by, cy + s * bx + c * by, bz])


def exit_velocity_world(cyaw: float, a: AugerParams) -> np.ndarray:
    """Exit velocity relative to the combine (3,) float64, world axes, m/s."""
    ex, ey, ez = a.exit_dir
    c, s = math.cos(cyaw), math.sin(cyaw)
    return a.exit_speed_mps * np.array([c * ex - s * ey, s * ex + c * ey, ez])


def flow_advance(level: float, on: bool, dt: float, a: AugerParams, command: float = 1.0) -> tuple[float, float]:
    """Advance the flow level (0..1, fraction of ``flow_m3ps``) over ``dt`` s towards ``command`` (0..1, the
    commanded fraction: 1 full flow, less a slowed auger) while on, towards 0 while off: a linear ramp, up at
    1 / ``spool_up_s`` and down at 1 / ``run_out_s``. Returns (new level, delivered volume m^3), the volume
    being the exact integral of flow_m3ps * level(t) over the step."""
    bound = command if on else 0.0
    up = level <= bound
    ramp = a.spool_up_s if up else a.run_out_s
    if ramp <= MIN_RAMP_S:
        return bound, a.flow_m3ps * bound * dt
    rate = (1.0 if up else -1.0) / ramp
    t_b = min(dt, (bound - level) / rate)                    # time to reach the bound (>= 0)
    integral = level * t_b + 0.5 * rate * t_b * t_b + bound * (dt - t_b)
    new = bound if t_b < dt else min(max(level + rate * dt, 0.0), 1.0)
    return new, a.flow_m3ps * integral


@dataclass(frozen=True)
class Impact:
    """Where the stream meets the first surface: world point (3,) m, grid point (3,) m, time of flight s,
    surface code (SURFACE_*)."""

    world: np.ndarray
    grid: np.ndarray
    time_s: float
    surface: int


def _surface(pts: np.ndarray, h: np.ndarray, cell: float, a: AugerParams) -> np.ndarray:
    """Surface height (n,) m (grid frame) under grid points (n, 3): the grain inside the interior, the rim band
    around it, the ground beyond (:func:`_surface_at` for one point, with its surface code)."""
    hl, hw = 0.5 * a.length_m, 0.5 * a.width_m
    ax, ay = np.abs(pts[:, 0] - hl), np.abs(pts[:, 1] - hw)
    inside = (ax < hl) & (ay < hw)
    band = (ax < hl + a.band_m) & (ay < hw + a.band_m)
    ij = (pts[:, :2] * (1.0 / cell)).astype(np.int64)
    np.maximum(ij, 0, out=ij)
    np.minimum(ij, (h.shape[0] - 1, h.shape[1] - 1), out=ij)
    return np.where(inside, h[ij[:, 0], ij[:, 1]], np.where(band, a.rim_top_m, -a.floor_height_m))


def _surface_at(x: float, y: float, h: np.ndarray, cell: float, a: AugerParams) -> tuple[float, int]:
    """:func:`_surface` of one grid point (x, y) m, on Python floats (same arithmetic): (height m, code)."""
    hl, hw = 0.5 * a.length_m, 0.5 * a.width_m
    ax, ay = abs(x - hl), abs(y - hw)
    if ax < hl and ay < hw:
        i = min(max(int(x * (1.0 / cell)), 0), h.shape[0] - 1)
        j = min(max(int(y * (1.0 / cell)), 0), h.shape[1] - 1)
        return float(h[i, j]), SURFACE_GRAIN
    if ax < hl + a.band_m and ay < hw + a.band_m:
        return a.rim_top_m, SURFACE_WALL
    return -a.floor_height_m, SURFACE_GROUND


def _points(spout: np.ndarray, vel: np.ndarray, s: np.ndarray, gravity: np.ndarray | None = None) -> np.ndarray:
    """Points (n, 3) of the parabola at times ``s`` (n,): gravity along -z, or the vector ``gravity`` (3,) m/s^2."""
    p = spout + vel * s[:, None]
    if gravity is None:
        p[:, 2] -= (0.5 * GRAVITY_MPS2) * s * s
    else:
        p += (0.5 * gravity) * (s * s)[:, None]
    return p


def first_surface(spout: np.ndarray, vel: np.ndarray, grid_from_world: np.ndarray, h: np.ndarray, cell: float,
                  a: AugerParams, tilted: bool = False) -> Impact:
    """First crossing of the parabola spout + vel s + g s^2/2 (world, m, m/s) with the surfaces.

    ``grid_from_world`` (4, 4): cart grid frame from world. ``h`` (nx, ny) grain heights m. The crossing is
    bracketed on a coarse sampling from where the stream falls through the highest surface down to the ground
    and refined once (time resolution ~4e-4 of that interval, sub-millimetre). ``tilted``: the cart grid frame
    is not level (a cart on the terrain), so gravity has components along the floor: the parabola is built with
    gravity rotated into the grid frame (the vertical fall times then use its z component).
    """
    r, t = grid_from_world[:3, :3], grid_from_world[:3, 3]
    sg, vg = r @ spout + t, r @ vel                  # level, the grid frame is the world turned about z: g stays -z
    grav = r @ np.array([0.0, 0.0, -GRAVITY_MPS2]) if tilted else None
    g_fall = -float(grav[2]) if tilted else GRAVITY_MPS2
    vz, z0 = float(vg[2]), float(sg[2])
    t_ground = _fall_time(z0, vz, -a.floor_height_m, g_fall) * 1.0001
    # nothing can be hit above the highest surface: start the search where the stream falls through it
    z_top = max(a.rim_top_m, float(h.max()))
    lo, hi = _fall_time(z0, vz, z_top, g_fall) if z0 > z_top else 0.0, t_ground
    d_lo = d_hi = 0.0
    for n in (_COARSE, _FINE):
        s = np.linspace(lo, hi, n)
        g = _points(sg, vg, s, grav)
        z = _surface(g, h, cell, a)
        d = g[:, 2] - z                               # height above the surface below, m
        below = np.flatnonzero(d <= 0.0)
        k = int(below[0]) if below.size else n - 1   # none: only through round-off at the ground
        if k == 0:
            lo = hi = float(s[0])
            d_lo, d_hi = 0.0, 0.0
            break
        lo, hi = float(s[k - 1]), float(s[k])
        d_lo, d_hi = float(d[k - 1]), float(d[k])
    # the crossing inside the last bracket, the surface taken as level there (linear in time)
    s_hit = lo + (hi - lo) * (d_lo / (d_lo - d_hi)) if d_lo > d_hi else hi
    sx, sy, _ = sg.tolist()
    vx, vy, _ = vg.tolist()
    gx, gy = sx + vx * s_hit, sy + vy * s_hit         # _points' arithmetic for one point
    if tilted:
        gx, gy = gx + 0.5 * float(grav[0]) * s_hit * s_hit, gy + 0.5 * float(grav[1]) * s_hit * s_hit
    z, code = _surface_at(gx, gy, h, cell, a)
    g = np.array([gx, gy, z])                          # on the surface it crossed (sub-millimetre correction)
    w = (g - t) @ r
    return Impact(world=w, grid=g, time_s=s_hit, surface=code)


def _fall_time(z0: float, vz: float, z: float, g: float = GRAVITY_MPS2) -> float:
    """Time s for z0 + vz s - g s^2 / 2 to come down to z (<= z0), m, m/s (``g`` m/s^2: the vertical part)."""
    return (vz + math.sqrt(vz * vz + 2.0 * g * max(z0 - z, 0.0))) / g


def stream_rows(spout: np.ndarray, vel: np.ndarray, t_impact: float, radius_m: float,
                out: np.ndarray | None = None) -> np.ndarray:
    """The stream centreline from the spout to the impact: (STREAM_ROWS, 4) float32 rows [x, y, z, radius]
    (world m). Written into ``out`` when given (zero copy)."""
    s = np.linspace(0.0, t_impact, STREAM_ROWS)
    out = np.empty((STREAM_ROWS, 4), np.float32) if out is None else out
    out[:, :3] = _points(spout, vel, s)
    out[:, 3] = radius_m
    return out


def landing_xy(spout: np.ndarray, vel: np.ndarray, z_plane: float,
               gravity: np.ndarray | None = None) -> tuple[float, float]:
    """x and y of :func:`landing_point` (same arithmetic on Python floats, so the same bits), m. ``gravity`` (3,)
    m/s^2 in the inputs' frame (a tilted cart's grid frame); None: -z."""
    sx, sy, sz = spout.tolist()
    if sz <= z_plane:
        return sx, sy
    vx, vy, vz = vel.tolist()
    if gravity is None:
        s = _fall_time(sz, vz, z_plane)
        return sx + vx * s, sy + vy * s
    gx, gy, gz = gravity.tolist()
    s = _fall_time(sz, vz, z_plane, -gz)
    return sx + vx * s + 0.5 * gx * s * s, sy + vy * s + 0.5 * gy * s * s


def landing_point(spout: np.ndarray, vel: np.ndarray, z_plane: float) -> np.ndarray:
    """Where the parabola descends through the horizontal plane z = ``z_plane`` (same frame as the inputs;
    gravity along -z), (3,) float64 m. Below the spout only; a plane above it gives the spout itself."""
    z0 = float(spout[2])
    if z0 <= z_plane:
        return spout.copy()
    return _points(spout, vel, np.array([_fall_time(z0, float(vel[2]), z_plane)]))[0]
