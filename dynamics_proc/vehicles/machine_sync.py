"""Machine Sync: the combine holds the tractor (and so the cart) at an offset setpoint.

The setpoint is the cart body origin's offset from the combine body origin in combine axes,
``(long_m, lat_m)`` (long > 0 ahead, lat > 0 to the left). With the cart straight behind the tractor the
tractor rear axle then sits at ``(long + tow_length + hitch_offset, lat)`` in combine axes; that point moves
rigidly with the combine, so its world velocity is known (feed-forward). The feedback law:

    w = v_setpoint + R_c diag(kp_long, kp_lat) R_c^T e        (e = setpoint - rear axle, world, m)
    v_cmd = clip(w . heading_tractor, 0, v_max)
    r_cmd = yaw_rate_combine + k_heading * wrap(atan2(w) - yaw_tractor)
    delta_cmd = clip(atan(wheelbase * r_cmd / max(v, V_STEER_MIN)), -delta_max, delta_max)

Linearised on a straight path this gives tau_d e'' + e' + kp_long e = 0 along the path (drivetrain lag
tau_d) and e'' + k_h e' + k_h kp_lat e = 0 across it (steering lag neglected); zero steady-state error.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from cosim.scenario.config import Scenario
from dynamics_proc.vehicles.motion import CX, CY, CYAW, TX, TY, TYAW, V, VehicleParams, cart_pose

__all__ = ["V_STEER_MIN_MPS", "W_HEADING_MIN_MPS", "SyncGains", "tractor_offset", "sync_command", "cart_offset",
           "wrap_angle"]

#: speed below which the steering law uses this speed instead (avoids dividing by ~0), m/s
V_STEER_MIN_MPS = 0.5
#: wanted speed below which the heading is held (direction undefined), m/s
W_HEADING_MIN_MPS = 0.05


@dataclass(frozen=True)
class SyncGains:
    """Feedback gains: position (1/s) along and across the combine path, heading (1/s)."""

    kp_long: float
    kp_lat: float
    k_heading: float

    @classmethod
    def from_scenario(cls, s: Scenario) -> "SyncGains":
        m = s.machine_sync
        return cls(m.kp_long, m.kp_lat, m.heading_gain_ps)


def wrap_angle(a: float) -> float:
    """Angle wrapped to [-pi, pi), rad."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def tractor_offset(setpoint: tuple[float, float], p: VehicleParams) -> tuple[float, float]:
    """Tractor rear-axle offset (combine axes, m) that puts the cart origin at ``setpoint`` (long, lat) m."""
    return setpoint[0] + p.tow_length_m + p.hitch_offset_m, setpoint[1]


def sync_command(x: np.ndarray | list[float], setpoint: tuple[float, float], p: VehicleParams,
                 g: SyncGains) -> tuple[float, float]:
    """Held input (v_cmd m/s, delta_cmd rad) for state ``x`` ((9,) array, or a list of its 9 floats) and cart
    offset ``setpoint`` (m, m)."""
    xs = x.tolist() if isinstance(x, np.ndarray) else x
    cyaw = xs[CYAW]
    c, s = math.cos(cyaw), math.sin(cyaw)
    ax, ay = tractor_offset(setpoint, p)
    ox, oy = c * ax - s * ay, s * ax + c * ay                 # offset in world axes
    ex = xs[CX] + ox - xs[TX]
    ey = xs[CY] + oy - xs[TY]
    el, et = c * ex + s * ey, -s * ex + c * ey                # error in combine axes
    fl, ft = g.kp_long * el, g.kp_lat * et
    wc = p.combine_yaw_rate_radps
    wx = p.combine_speed_mps * c - wc * oy + c * fl - s * ft
    wy = p.combine_speed_mps * s + wc * ox + s * fl + c * ft
    tyaw = xs[TYAW]
    v_cmd = wx * math.cos(tyaw) + wy * math.sin(tyaw)
    v_cmd = min(max(v_cmd, 0.0), p.max_speed_mps)
    r_cmd = wc
    if math.hypot(wx, wy) > W_HEADING_MIN_MPS:
        r_cmd += g.k_heading * wrap_angle(math.atan2(wy, wx) - tyaw)
    d_cmd = math.atan(p.wheelbase_m * r_cmd / max(xs[V], V_STEER_MIN_MPS))
    d_cmd = min(max(d_cmd, -p.steer_max_rad), p.steer_max_rad)
    return v_cmd, d_cmd


def cart_offset(x: np.ndarray, p: VehicleParams) -> tuple[float, float]:
    """Actual cart body origin offset from the combine body origin in combine axes (long m, lat m)."""
    px, py, _ = cart_pose(x, p)
    cyaw = float(x[CYAW])
    c, s = math.cos(cyaw), math.sin(cyaw)
    dx, dy = px - float(x[CX]), py - float(x[CY])
    return c * dx + s * dy, -s * dx + c * dy
