"""Feed-forward of the auger target through turns: where the spout sits over the cart in a steady turn.

Machine Sync holds the tractor's rear axle at its setpoint in combine axes (dynamics_proc.vehicles.machine_sync), with
zero steady-state error also on an arc. The towed cart does not follow the setpoint there: it off-tracks towards
the turn's centre and turns relative to the combine, so the spout moves along the cart (the paper's curved
pass; Deere moves the spout ahead of a turn for the same reason). In a steady turn at yaw rate w the whole
train turns rigidly about the centre O = (0, v / w) (combine axes, the combine body origin at 0):

* the rear axle A sits at the setpoint and moves along w z x (A - O), its heading;
* the hitch is H = A - h t (t the tractor's heading, h the hitch offset);
* the cart axle P (the cart body origin) moves without side slip, so (H - P) is perpendicular to (P - O):
  |P - O|^2 = |H - O|^2 - Lt^2, P = H - Lt c with c . (H - O) = Lt (Lt the tow length), c the cart heading
  on the side of the motion.

Off-tracking moves the cart mostly sideways (0.57 m outwards on a 60 m radius at the default offsets) and turns
it, while the spout's position along the cart hardly changes (millimetres). :func:`turn_compensation` gives the
lateral setpoint correction that keeps the spout over the same line of the cart and the small shift along the
cart that remains; the built-in controller applies both ahead of the turn (``controller.coping.feedforward``)
instead of waiting for the impact to drift towards a wall and for its learnt bias. Exact for the kinematic model
at steady state; the transients (the drivetrain and steering lags, the trailer's settling) are left to the
feedback.
"""
from __future__ import annotations

import math

import numpy as np

from cosim.world.geometry import apply, invert, vehicle_pose
from dynamics_proc.vehicles.machine_sync import tractor_offset
from dynamics_proc.vehicles.motion import VehicleParams

__all__ = ["SECANT_STEPS", "steady_cart_offset", "turn_compensation"]

#: secant steps of :func:`turn_compensation` (the spout's grid y is nearly linear in the lateral setpoint)
SECANT_STEPS = 4


def steady_cart_offset(yaw_rate_radps: float, setpoint: tuple[float, float],
                       p: VehicleParams) -> tuple[float, float, float]:
    """The cart body origin (long m, lat m) and heading (rad) in combine axes in a steady turn at
    ``yaw_rate_radps`` (> 0 left) with the Machine Sync ``setpoint`` (long, lat) m; the setpoint itself and 0 on a
    straight path."""
    if yaw_rate_radps == 0.0 or p.combine_speed_mps == 0.0:
        return setpoint[0], setpoint[1], 0.0
    w = yaw_rate_radps
    ox, oy = 0.0, p.combine_speed_mps / w                       # the turn's centre, combine axes
    ax, ay = tractor_offset(setpoint, p)
    vx, vy = -(ay - oy) * w, (ax - ox) * w                      # the rear axle's velocity w z x (A - O)
    speed = math.hypot(vx, vy)
    hx, hy = ax - p.hitch_offset_m * vx / speed, ay - p.hitch_offset_m * vy / speed
    dx, dy = hx - ox, hy - oy
    dist = math.hypot(dx, dy)
    if dist <= p.tow_length_m:
        raise ValueError(f"a steady turn of radius {abs(oy):.1f} m cannot be towed: the hitch is {dist:.1f} m from "
                         f"its centre, within the {p.tow_length_m:.1f} m tow length")
    ux, uy = dx / dist, dy / dist
    cos_b = p.tow_length_m / dist
    sin_b = math.copysign(math.sqrt(1.0 - cos_b * cos_b), w)
    cx, cy = cos_b * ux - sin_b * uy, cos_b * uy + sin_b * ux   # cos b u + sin b (z x u), on the moving side
    return hx - p.tow_length_m * cx, hy - p.tow_length_m * cy, math.atan2(cy, cx)


def _spout_grid(spout_body: np.ndarray, offset: tuple[float, float, float],
                grid_from_cart_body: np.ndarray) -> tuple[float, float]:
    """The spout's cart grid (x, y), m, with the cart at ``offset`` (long, lat, yaw) in combine axes."""
    px, py, pyaw = offset
    g = apply(grid_from_cart_body @ invert(vehicle_pose(px, py, pyaw)), spout_body)
    return float(g[0]), float(g[1])


def turn_compensation(yaw_rate_radps: float, setpoint: tuple[float, float], p: VehicleParams, spout_body: np.ndarray,
                      grid_from_cart_body: np.ndarray, iterations: int = SECANT_STEPS) -> tuple[float, float]:
    """How to keep the spout over the same line of the cart in a steady turn at ``yaw_rate_radps``: (lateral
    setpoint correction m, the spout's remaining shift along grid x m). The correction moves Machine Sync's
    lateral setpoint so that the spout's cart grid y is its straight-path value (the off-tracking cancelled:
    secant steps on the closed form, converged to well under a millimetre in ``iterations``); the shift along x
    is what the controller's longitudinal target must then allow for. ``spout_body`` (3,) m: the spout in the
    combine body frame; ``grid_from_cart_body`` (4, 4): the cart grid frame from the cart body frame. Exactly
    (0.0, 0.0) on a straight path."""
    if yaw_rate_radps == 0.0:
        return 0.0, 0.0
    long_m, lat_m = setpoint
    x0, y0 = _spout_grid(spout_body, (long_m, lat_m, 0.0), grid_from_cart_body)

    def grid_at(dlat: float) -> tuple[float, float]:
        return _spout_grid(spout_body, steady_cart_offset(yaw_rate_radps, (long_m, lat_m + dlat), p),
                           grid_from_cart_body)

    a, (_, ya) = 0.0, grid_at(0.0)
    b, (_, yb) = 1.0, grid_at(1.0)
    for _ in range(iterations):
        if yb == ya:
            break
        a, ya, b = b, yb, b - (yb - y0) * (b - a) / (yb - ya)
        yb = grid_at(b)[1]
    return b, grid_at(b)[0] - x0


