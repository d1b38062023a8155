"""A representative offloading frame built from the scenario alone, for the renderer's tests and benchmarks.

The vehicles stand where Machine Sync holds them at the start (cart at the configured offsets beside the
combine, tractor ahead of the cart on its tongue), the auger is swung out, the grain stream falls
ballistically from the spout, and the cart holds the initial fill plus a conical pile under the impact point.
It is a fixed, deterministic geometry (no dynamics): dynamics_proc owns the real state.
"""
from __future__ import annotations

import math

import numpy as np

from cosim.scenario.config.scenario import Scenario
from cosim.world.geometry import apply, cart_grid_from_body, invert, vehicle_pose
from cosim.world.scene import STREAM_ROWS

__all__ = ["GRAVITY_MPS2", "PILE_HEIGHT_M", "STREAM_SAMPLES", "sample_frame"]

#: gravitational acceleration, m/s^2
GRAVITY_MPS2 = 9.81
#: stream polyline points used by the sample frame
STREAM_SAMPLES = 24
#: height of the sample pile above the initial fill, m
PILE_HEIGHT_M = 0.6


def _spout(s: Scenario) -> tuple[np.ndarray, np.ndarray]:
    """Spout position and unit auger direction in the combine body frame."""
    a = s.auger
    sw, el = math.radians(a.swing_deg), math.radians(a.elevation_deg)
    u = np.array([math.cos(el) * math.cos(sw), math.cos(el) * math.sin(sw), math.sin(el)])
    return np.asarray(a.pivot_xyz_m) + a.length_m * u, u


def sample_frame(scenario: Scenario, t_s: float = 0.0) -> tuple[dict[str, float], np.ndarray, np.ndarray]:
    """(dyn_state mapping, heightmap (nx, ny) float32 m, stream (64, 4) float32) of a sample frame at time
    ``t_s`` (the vehicles drive along the combine heading at the harvest speed)."""
    s = scenario
    yaw = math.radians(s.combine.heading_deg)
    combine = vehicle_pose(s.combine.start_xy_m[0], s.combine.start_xy_m[1], yaw)
    combine[:3, 3] += s.combine.speed_mps * t_s * np.array([math.cos(yaw), math.sin(yaw), 0.0])
    cart_xy = apply(combine, [s.machine_sync.longitudinal_offset_m, s.machine_sync.lateral_offset_m, 0.0])
    cart = vehicle_pose(cart_xy[0], cart_xy[1], yaw)
    ahead = s.cart.interior_length_m / 2.0 + s.cart.wall_thickness_m + s.cart.tongue_length_m + s.tractor.length_m / 2.0
    tractor_xy = apply(cart, [ahead, 0.0, 0.0])
    spout_b, u = _spout(s)
    spout = apply(combine, spout_b)
    # ballistic stream: exit speed along the auger's horizontal direction, tipped down by exit_down_deg
    down = math.radians(s.auger.exit_down_deg)
    h_dir = combine[:3, :3] @ np.array([u[0], u[1], 0.0]) / max(math.hypot(u[0], u[1]), 1e-12)
    v0 = s.auger.exit_speed_mps * (math.cos(down) * h_dir + np.array([0.0, 0.0, -math.sin(down)]))
    floor_z = s.cart.floor_height_m
    fill = s.grain.initial_fill_m
    # time to fall to the grain top (initial fill + pile)
    dz = spout[2] - (floor_z + fill + PILE_HEIGHT_M)
    t_fall = (v0[2] + math.sqrt(v0[2] ** 2 + 2.0 * GRAVITY_MPS2 * max(dz, 0.0))) / GRAVITY_MPS2
    tt = np.linspace(0.0, t_fall, STREAM_SAMPLES)[:, None]
    pts = spout + v0 * tt + np.array([0.0, 0.0, -0.5 * GRAVITY_MPS2]) * tt**2
    stream = np.zeros((STREAM_ROWS, 4), np.float32)
    stream[:STREAM_SAMPLES, :3] = pts
    stream[:STREAM_SAMPLES, 3] = s.auger.stream_radius_m
    # heightmap: initial fill plus a cone of slope tan(repose) under the impact point
    nx = int(round(s.cart.interior_length_m / s.grain.cell_m))
    ny = int(round(s.cart.interior_width_m / s.grain.cell_m))
    impact_g = apply(cart_grid_from_body(s.cart) @ invert(cart), pts[-1])
    xc = (np.arange(nx) + 0.5) * s.grain.cell_m
    yc = (np.arange(ny) + 0.5) * s.grain.cell_m
    r = np.hypot(xc[:, None] - impact_g[0], yc[None, :] - impact_g[1])
    pile = np.maximum(PILE_HEIGHT_M - r * math.tan(s.crop.repose_rad), 0.0)
    heights = np.minimum(fill + pile, s.cart.interior_depth_m).astype(np.float32)
    state = {
        "t_s": float(t_s),
        "combine_x_m": float(combine[0, 3]), "combine_y_m": float(combine[1, 3]), "combine_yaw_rad": yaw,
        "tractor_x_m": float(tractor_xy[0]), "tractor_y_m": float(tractor_xy[1]), "tractor_yaw_rad": yaw,
        "cart_x_m": float(cart_xy[0]), "cart_y_m": float(cart_xy[1]), "cart_yaw_rad": yaw,
        "spout_x_m": float(spout[0]), "spout_y_m": float(spout[1]), "spout_z_m": float(spout[2]),
        "auger_on": 1.0, "flow_m3ps": s.auger.flow_m3ps, "stream_points": float(STREAM_SAMPLES),
        "impact_x_m": float(pts[-1, 0]), "impact_y_m": float(pts[-1, 1]), "impact_z_m": float(pts[-1, 2]),
        "impact_valid": 1.0,
    }
    return state, heights, stream
