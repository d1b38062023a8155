"""The ``dyn_state`` record of a world (dynamics_proc.blocks names the fields): :func:`signals`."""
from __future__ import annotations

import math
from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np

from cosim.world.geometry import POSE_3D_FIELDS
from dynamics_proc.blocks import SECTION_FIELD
from dynamics_proc.grain.fill import volume
from dynamics_proc.vehicles.fieldsync import SLIP_MAX, combine_motion, flow_factor
from dynamics_proc.vehicles.ground import machine_poses, planar_poses
from dynamics_proc.vehicles.machine_sync import cart_offset
from dynamics_proc.vehicles.motion import CX, CY, CYAW, DELTA, V, cart_pose, tractor_pose

if TYPE_CHECKING:
    from dynamics_proc.state import ModelParams, World

__all__ = ["signals"]


def signals(w: "World", p: "ModelParams") -> dict[str, float]:
    """The ``dyn_state`` fields of world ``w`` (names carry units; see blocks.py)."""
    x, vp = w.x, p.vehicles
    tx, ty, tyaw = tractor_pose(x, vp)
    px, py, pyaw = cart_pose(x, vp)
    sp, _, spg, _ = w.spout
    long_m, lat_m = cart_offset(x, vp)
    in_cart = volume(w.heights, p.grid) - w.initial_m3
    speed, yaw_rate = combine_motion(p.field, vp, w.t_s)
    factor = flow_factor(p.field, w.field)
    d = {
        "t_s": w.t_s, "frame": w.frame,
        "combine_x_m": float(x[CX]), "combine_y_m": float(x[CY]), "combine_yaw_rad": float(x[CYAW]),
        "combine_speed_mps": speed, "combine_yaw_rate_radps": yaw_rate,
        "tractor_x_m": tx, "tractor_y_m": ty, "tractor_yaw_rad": tyaw, "tractor_speed_mps": float(x[V]),
        "tractor_steer_rad": float(x[DELTA]),
        "cart_x_m": px, "cart_y_m": py, "cart_yaw_rad": pyaw,
        **_ground_fields(x, p),
        "spout_x_m": float(sp[0]), "spout_y_m": float(sp[1]), "spout_z_m": float(sp[2]),
        "auger_on": int(w.out.auger_on), "flow_level": w.flow_level,
        "flow_m3ps": w.flow_level * p.auger.flow_m3ps * factor, "flow_factor": factor,
        "impact_x_m": float(w.impact.world[0]), "impact_y_m": float(w.impact.world[1]),
        "impact_z_m": float(w.impact.world[2]), "impact_valid": int(w.stream_points > 0),
        "impact_surface": w.impact.surface, "impact_gx_m": float(w.impact.grid[0]),
        "impact_gy_m": float(w.impact.grid[1]), "impact_gz_m": float(w.impact.grid[2]),
        "stream_points": w.stream_points,
        "desired_auger_x_m": w.out.desired_m, "control_effort_m": w.out.effort_m,
        "nudge_m": w.setpoint[0] + p.signal_offset_m, "actual_auger_x_m": float(spg[0]),
        "actual_auger_y_m": float(spg[1]), "nudge_cmd": w.out.nudge, "nudge_count": w.nudges,
        "setpoint_long_m": w.setpoint[0], "setpoint_lat_m": w.setpoint[1],
        "offset_long_err_m": long_m - w.setpoint[0], "offset_lat_err_m": lat_m - w.setpoint[1],
        "target_section": w.out.target + 1, "all_full": int(w.out.all_full),
        "measurement_seen": int(w.out.seen), "control_bias_m": w.out.bias_m, "target_fill_m": p.control.target_m,
        "control_mode": w.out.mode, "hold_reason": w.out.hold_reason, "estimate_sigma_m": w.out.sigma_m,
        "full_lead_m": w.out.lead_m, "lateral_feedforward_m": w.out.lateral_m,
        "delivered_m3": w.delivered_m3, "in_cart_m3": in_cart, "spilled_m3": w.spilled_m3,
        "spilled_outside_m3": w.spilled_outside_m3, "cart_grain_m3": w.initial_m3 + in_cart,
        "peak_height_m": float(w.heights.max()),
        **_field_fields(w, p),
    }
    d.update(zip(_section_names(p.control.sections), w.out.fullness.tolist()))
    return d


#: the terrain fields of dyn_state on flat ground
_LEVEL = {f"{n}_{f}": 0.0 for n in ("combine", "tractor", "cart") for f in POSE_3D_FIELDS}


def _ground_fields(x: np.ndarray, p: "ModelParams") -> dict[str, float]:
    """``<body>_{z_m, roll_rad, pitch_rad}`` of the three bodies on the terrain (all 0.0 on flat ground)."""
    if p.stance is None:
        return _LEVEL
    poses = machine_poses(p.stance, *planar_poses(x, p.vehicles))
    return {f"{n}_{f}": v for n, pose in zip(("combine", "tractor", "cart"), poses)
            for f, v in zip(POSE_3D_FIELDS, pose[3:])}


def _field_fields(w: "World", p: "ModelParams") -> dict[str, float]:
    """The field conditions' fields: the tractor's GNSS position error relative to the combine's, combine axes
    (along, across; m), and its wheel slip (all 0.0 on an ideal field)."""
    if w.field is None:
        return _IDEAL
    e = w.field.gnss
    yaw = float(w.x[CYAW])
    dx, dy = float(e[2] - e[0]), float(e[3] - e[1])
    c, s = math.cos(yaw), math.sin(yaw)
    keep = 1.0 - min(max(p.field.slip_mean + w.field.slip, 0.0), SLIP_MAX)
    return {"gnss_error_long_m": c * dx + s * dy, "gnss_error_lat_m": -s * dx + c * dy, "tractor_slip": 1.0 - keep}


#: the field-condition fields on an ideal field
_IDEAL = {"gnss_error_long_m": 0.0, "gnss_error_lat_m": 0.0, "tractor_slip": 0.0}


@lru_cache(maxsize=4)
def _section_names(sections: int) -> tuple[str, ...]:
    """The dyn_state names of the section fullness fields, 1..N."""
    return tuple(SECTION_FIELD.format(k=k + 1) for k in range(sections))
