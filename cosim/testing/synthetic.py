"""Analytic scenes with exact ray casts, for tests and benchmarks of the perception stage.

Shapes are given in one common frame (whatever the caller uses: sensor or vehicle body frame). ``raycast``
returns the exact distance along each unit ray to the first surface, inf on a miss. ``render_depth`` turns that
into a camera's planar-depth image and ``encode_linear`` into the linear-byte RGBA8 of Eqs 1-2, so a test can
produce exactly what the renderer would send. The grain cart scene mirrors ``cosim.scenario.config.Cart``: interior
|x| <= L/2, |y| <= W/2 in the cart body frame, walls ``rim_width_m`` thick from ``WALL_BOTTOM_M`` to the rim
top, a floor, a grain height field over the floor and an optional vertical grain stream.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from cosim.scenario.config import Cart, Codec
from cosim.world.camera import Pinhole, Rig, RigCamera, yaw_transform
from cosim.world.geometry import apply, invert

__all__ = [
    "Plane", "Box", "Cylinder", "HeightField", "raycast", "render_depth", "encode_linear", "cart_shapes",
    "WALL_BOTTOM_M", "stitched_rig",
]

#: height above ground of the bottom of the synthetic cart's walls, m
WALL_BOTTOM_M = 0.4
#: march step of the height-field intersection before bisection, m
HF_STEP_M = 0.02
_BISECT = 30


@dataclass(frozen=True)
class Plane:
    """Infinite plane n . p = offset (``normal`` unit (3,))."""

    normal: tuple[float, float, float]
    offset: float

    def hit(self, o: np.ndarray, d: np.ndarray) -> np.ndarray:
        n = np.asarray(self.normal, dtype=np.float64)
        den = d @ n
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (self.offset - o @ n) / den
        return np.where((t > 0) & np.isfinite(t), t, np.inf)


@dataclass(frozen=True)
class Box:
    """Box lo <= p <= hi in the frame ``frame_from_box`` maps from (4 x 4, identity: axis-aligned)."""

    lo: tuple[float, float, float]
    hi: tuple[float, float, float]
    frame_from_box: np.ndarray = field(default_factory=lambda: np.eye(4))

    def hit(self, o: np.ndarray, d: np.ndarray) -> np.ndarray:
        inv = invert(self.frame_from_box)
        ob = apply(inv, o)
        db = d @ inv[:3, :3].T
        lo, hi = np.asarray(self.lo), np.asarray(self.hi)
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = (lo - ob) / db
            t2 = (hi - ob) / db
        t1 = np.where(np.isnan(t1), -np.inf, t1)
        t2 = np.where(np.isnan(t2), np.inf, t2)
        tnear = np.minimum(t1, t2).max(axis=-1)
        tfar = np.maximum(t1, t2).min(axis=-1)
        ok = (tfar >= tnear) & (tfar > 0)
        return np.where(ok, np.where(tnear > 0, tnear, np.inf), np.inf)


@dataclass(frozen=True)
class Cylinder:
    """Vertical (along +z of the frame) solid cylinder of ``radius`` around (cx, cy), z_lo <= z <= z_hi."""

    cx: float
    cy: float
    radius: float
    z_lo: float
    z_hi: float

    def hit(self, o: np.ndarray, d: np.ndarray) -> np.ndarray:
        px, py = o[..., 0] - self.cx, o[..., 1] - self.cy
        a = d[..., 0] ** 2 + d[..., 1] ** 2
        b = 2 * (px * d[..., 0] + py * d[..., 1])
        c = px**2 + py**2 - self.radius**2
        disc = b * b - 4 * a * c
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (-b - np.sqrt(disc)) / (2 * a)
        z = o[..., 2] + t * d[..., 2]
        side = (disc >= 0) & (a > 0) & (t > 0) & (z >= self.z_lo) & (z <= self.z_hi)
        t_side = np.where(side, t, np.inf)
        t_cap = Plane((0.0, 0.0, 1.0), self.z_hi).hit(o, d)
        q = o + np.where(np.isfinite(t_cap), t_cap, 0.0)[..., None] * d
        cap = np.isfinite(t_cap) & ((q[..., 0] - self.cx) ** 2 + (q[..., 1] - self.cy) ** 2 <= self.radius**2)
        return np.minimum(t_side, np.where(cap, t_cap, np.inf))


@dataclass(frozen=True)
class HeightField:
    """Surface z = height(x, y) (vectorised callable, m) over x0 <= x <= x1, y0 <= y <= y1 of the frame; the
    solid lies between ``z_min`` and the surface (``height`` must stay below ``z_max``)."""

    height: Callable[[np.ndarray, np.ndarray], np.ndarray]
    x0: float
    x1: float
    y0: float
    y1: float
    z_min: float
    z_max: float

    def _slab(self, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        lo = np.array([self.x0, self.y0, self.z_min])
        hi = np.array([self.x1, self.y1, self.z_max])
        with np.errstate(divide="ignore", invalid="ignore"):
            t1, t2 = (lo - o) / d, (hi - o) / d
        t1 = np.where(np.isnan(t1), -np.inf, t1)
        t2 = np.where(np.isnan(t2), np.inf, t2)
        return np.maximum(np.minimum(t1, t2).max(axis=-1), 0.0), np.maximum(t1, t2).min(axis=-1)

    def hit(self, o: np.ndarray, d: np.ndarray) -> np.ndarray:
        shape = d.shape[:-1]
        oo, dd = o.reshape(-1, 3), d.reshape(-1, 3)
        t_in, t_out = self._slab(oo, dd)
        out = np.full(oo.shape[0], np.inf)
        act = np.flatnonzero(t_out >= t_in)
        if act.size == 0:
            return out.reshape(shape)

        def above(i: np.ndarray, t: np.ndarray) -> np.ndarray:
            p = oo[i] + t[:, None] * dd[i]
            return p[:, 2] - self.height(p[:, 0], p[:, 1])

        start = above(act, t_in[act])
        hit0 = start <= 0                                   # starts inside the solid: hit at entry
        out[act[hit0]] = t_in[act[hit0]]
        act = act[~hit0]
        t_prev = t_in[act]
        while act.size:
            t = np.minimum(t_prev + HF_STEP_M, t_out[act])
            f = above(act, t)
            cross = f <= 0
            if cross.any():
                i = act[cross]
                a, b = t_prev[cross], t[cross]
                for _ in range(_BISECT):
                    m = 0.5 * (a + b)
                    fm = above(i, m)
                    a, b = np.where(fm > 0, m, a), np.where(fm > 0, b, m)
                out[i] = 0.5 * (a + b)
            keep = ~cross & (t < t_out[act])
            act, t_prev = act[keep], t[keep]
        return out.reshape(shape)


Shape = Plane | Box | Cylinder | HeightField


def raycast(shapes: Sequence[Shape], origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Exact distance (...,) float64, m, along unit ``directions`` (..., 3) from ``origins`` (..., 3) to the
    first surface of any shape; inf on a miss."""
    d = np.asarray(directions, dtype=np.float64)
    o = np.broadcast_to(np.asarray(origins, dtype=np.float64), d.shape)
    t = np.full(d.shape[:-1], np.inf)
    for s in shapes:
        t = np.minimum(t, s.hit(o, d))
    return t


def render_depth(shapes: Sequence[Shape], frame_from_sensor: np.ndarray, cam: RigCamera) -> np.ndarray:
    """Planar depth image (H, W) float64, m, of ``cam`` (NaN on a miss). Shapes live in the frame that
    ``frame_from_sensor`` (4 x 4) maps the sensor frame into."""
    rays = cam.intrinsics.ray_directions()                                 # (H, W, 3) camera frame
    frame_from_cam = frame_from_sensor @ cam.sensor_from_camera
    d = rays @ frame_from_cam[:3, :3].T
    o = np.broadcast_to(frame_from_cam[:3, 3], d.shape)
    t = raycast(shapes, o, d)
    z = t * rays[..., 2]
    return np.where(np.isfinite(z), z, np.nan)


def encode_linear(depth_m: np.ndarray, codec: Codec) -> np.ndarray:
    """Eqs 1-2 with linear stored bytes: (H, W) planar depth m (NaN = no hit) -> (H, W, 4) uint8 RGBA.

    A = 0 for no hit or d >= alpha; with ``codec.gamma_mode == "mishandled"`` the bytes hold x^gamma.
    """
    d_cm = np.asarray(depth_m, dtype=np.float64) * 100.0
    hit = np.isfinite(d_cm) & (d_cm < codec.alpha_cm)
    dc = np.where(hit, d_cm, 0.0)
    xr = np.minimum(dc / codec.alpha_cm, 1.0)
    xb = np.mod(dc, codec.beta_cm) / codec.beta_cm
    if codec.gamma_mode == "mishandled":
        xr, xb = xr**codec.gamma, xb**codec.gamma
    out = np.zeros(d_cm.shape + (4,), dtype=np.uint8)
    r = np.rint(255.0 * xr).astype(np.uint8)
    out[..., 0] = r
    out[..., 1] = r
    out[..., 2] = np.rint(255.0 * xb).astype(np.uint8)
    out[..., 3] = np.where(hit, 255, 0).astype(np.uint8)
    return out


def cart_shapes(cart: Cart, frame_from_cartbody: np.ndarray, grain_height: Callable | None = None,
                stream_xy_grid: tuple[float, float] | None = None, stream_top_m: float = 4.5,
                stream_radius_m: float = 0.15, ground: bool = True) -> list[Shape]:
    """A grain cart in a frame: ground z = 0 (if ``ground``; the frame must be level), 4 walls, floor, grain.

    ``grain_height(gx, gy)``: grain height above the floor in the cart grid frame (m; None: empty cart).
    ``stream_xy_grid``: (gx, gy) of a vertical stream (grid frame) from ``stream_top_m`` above ground down to
    the floor. Everything is built in the cart body frame and mapped by ``frame_from_cartbody`` (4 x 4).
    """
    L, W, rw = cart.interior_length_m, cart.interior_width_m, cart.rim_width_m
    top, fl = cart.rim_top_m, cart.floor_height_m
    T = frame_from_cartbody
    shapes: list[Shape] = [
        Box((L / 2, -W / 2 - rw, WALL_BOTTOM_M), (L / 2 + rw, W / 2 + rw, top), T),
        Box((-L / 2 - rw, -W / 2 - rw, WALL_BOTTOM_M), (-L / 2, W / 2 + rw, top), T),
        Box((-L / 2, W / 2, WALL_BOTTOM_M), (L / 2, W / 2 + rw, top), T),
        Box((-L / 2, -W / 2 - rw, WALL_BOTTOM_M), (L / 2, -W / 2, top), T),
        Box((-L / 2, -W / 2, WALL_BOTTOM_M), (L / 2, W / 2, fl), T),
    ]
    if ground:
        shapes.append(Plane((0.0, 0.0, 1.0), 0.0))
    # body -> grid: gx = L/2 - bx, gy = W/2 - by
    if grain_height is not None:
        if not np.allclose(T[:3, :3], np.eye(3)) and not np.allclose(T[2, :3], (0, 0, 1)):
            raise ValueError("grain height field needs a level cart frame")
        shapes.append(_GrainField(grain_height, cart, T))
    if stream_xy_grid is not None:
        bx, by = L / 2 - stream_xy_grid[0], W / 2 - stream_xy_grid[1]
        p = apply(T, np.array([bx, by, 0.0]))
        shapes.append(Cylinder(float(p[0]), float(p[1]), stream_radius_m, fl, stream_top_m))
    return shapes


@dataclass(frozen=True)
class _GrainField:
    """Height field of grain in a (level) cart: frame -> body -> grid coordinates."""

    grain_height: Callable
    cart: Cart
    frame_from_body: np.ndarray

    def hit(self, o: np.ndarray, d: np.ndarray) -> np.ndarray:
        inv = invert(self.frame_from_body)
        ob, db = apply(inv, o), d @ inv[:3, :3].T
        L, W, fl = self.cart.interior_length_m, self.cart.interior_width_m, self.cart.floor_height_m
        hf = HeightField(
            lambda x, y: fl + self.grain_height(L / 2 - x, W / 2 - y), -L / 2, L / 2, -W / 2, W / 2,
            fl, self.cart.rim_top_m + 1.0,
        )
        return hf.hit(ob, db)


def stitched_rig(n: int = 2, width: int = 640, height: int = 480, hfov_deg: float = 60.0,
                 yaw_step_deg: float | None = None, offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0),
                 pitch_deg: float = 0.0) -> Rig:
    """A rig of ``n`` cameras side by side, turned ``yaw_step_deg`` apart (default: hfov - 5 deg overlap),
    symmetric about the sensor's forward axis, all at ``offset_m`` (sensor frame, m) from the LiDAR origin and
    pitched ``pitch_deg`` (positive looks up). For tests and benchmarks; the run uses cosim.world.rig."""
    step = hfov_deg - 5.0 if yaw_step_deg is None else yaw_step_deg
    cams = []
    c, s = math.cos(math.radians(pitch_deg)), math.sin(math.radians(pitch_deg))
    pitch = np.eye(4)
    pitch[1:3, 1:3] = [[c, s], [-s, c]]                 # about -X: +Z towards +Y for positive pitch
    for k in range(n):
        yaw = math.radians((k - (n - 1) / 2.0) * step)
        t = yaw_transform(-yaw) @ pitch
        t[:3, 3] = offset_m
        cams.append(RigCamera(f"cam{k}", Pinhole(width, height, math.radians(hfov_deg)), t))
    return Rig(tuple(cams))
