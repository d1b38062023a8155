"""Continuous vehicle model: combine on its path, tractor (kinematic bicycle with lags) towing the cart.

State vector ``x`` (9,) float64, world frame (x forward at t = 0, y left, z up), SI units:

====  ==========  =======================================================================
 idx  name        meaning
====  ==========  =======================================================================
  0   cx          combine body origin x, m
  1   cy          combine body origin y, m
  2   cyaw        combine heading, rad
  3   tx          tractor rear-axle centre x, m
  4   ty          tractor rear-axle centre y, m
  5   tyaw        tractor heading, rad
  6   v           tractor speed along its heading, m/s (drivetrain lag state)
  7   delta       tractor front steering angle, rad (steering lag state)
  8   pyaw        cart heading, rad (single-axle trailer, axle under the interior centre)
====  ==========  =======================================================================

Input ``u`` = (v_cmd m/s, delta_cmd rad), held constant over a step (zero-order hold).
The combine drives at constant speed on a straight line or an arc turning left (yaw rate v / R).
Drivetrain: dv/dt = clip((v_cmd - v) / tau_d, -brake_max, accel_max); steering:
d delta/dt = clip((delta_cmd - delta) / tau_s, -rate_max, rate_max). Trailer (hitch at distance h behind the
rear axle, hitch-to-cart-axle distance Lt): d pyaw/dt = (v sin(tyaw - pyaw) - h r cos(tyaw - pyaw)) / Lt with
r = v tan(delta) / wheelbase the tractor yaw rate.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from cosim.scenario.config import Scenario

__all__ = [
    "N_STATES", "CX", "CY", "CYAW", "TX", "TY", "TYAW", "V", "DELTA", "PYAW", "VehicleParams",
    "derivative", "kinematic_derivative", "towing_rates", "lag_exact", "lag_exact_pair", "lag_integral",
    "cart_pose", "tractor_pose", "hitch_point", "initial_state", "combine_advance",
]

N_STATES = 9
CX, CY, CYAW, TX, TY, TYAW, V, DELTA, PYAW = range(N_STATES)


@dataclass(frozen=True)
class VehicleParams:
    """Plain-float parameters of the vehicle model (SI units), derived once from the scenario."""

    combine_speed_mps: float
    combine_yaw_rate_radps: float
    wheelbase_m: float
    hitch_offset_m: float
    tow_length_m: float
    rear_axle_x_m: float
    drivetrain_tau_s: float
    accel_max_mps2: float
    brake_max_mps2: float
    steer_tau_s: float
    steer_max_rad: float
    steer_rate_max_radps: float
    max_speed_mps: float
    ground_keep: float = 1.0         # ground speed / wheel speed, 1 - the tractor's wheel slip (docs/field.md)

    @classmethod
    def from_scenario(cls, s: Scenario) -> "VehicleParams":
        c, t, k = s.combine, s.tractor, s.cart
        yaw_rate = c.speed_mps / c.path_radius_m if c.path == "arc" else 0.0
        return cls(
            combine_speed_mps=c.speed_mps, combine_yaw_rate_radps=yaw_rate,
            wheelbase_m=t.wheelbase_m, hitch_offset_m=t.hitch_offset_m,
            tow_length_m=k.interior_length_m / 2.0 + k.wall_thickness_m + k.tongue_length_m,
            rear_axle_x_m=t.rear_axle_x_m, drivetrain_tau_s=t.drivetrain_tau_s,
            accel_max_mps2=t.accel_max_mps2, brake_max_mps2=t.brake_max_mps2, steer_tau_s=t.steer_tau_s,
            steer_max_rad=math.radians(t.steer_max_deg), steer_rate_max_radps=math.radians(t.steer_rate_max_degps),
            max_speed_mps=t.max_speed_mps,
        )


def _clip(a: float, lo: float, hi: float) -> float:
    return lo if a < lo else hi if a > hi else a


def towing_rates(v: float, r: float, tyaw: float, pyaw: float, hitch_m: float, tow_m: float) -> tuple[float, ...]:
    """The tractor-and-cart rows of :func:`kinematic_derivative`: (cart yaw rate dp rad/s, tractor velocity
    vx, vy m/s, world frame) at speed ``v`` m/s, tractor yaw rate ``r`` rad/s, headings ``tyaw`` and ``pyaw``
    rad, hitch offset and tow length m (also called stage by stage by the inlined RK4 of
    ``integrators.step_exponential_values``)."""
    rel = tyaw - pyaw
    return ((v * math.sin(rel) - hitch_m * r * math.cos(rel)) / tow_m, v * math.cos(tyaw), v * math.sin(tyaw))


def combine_advance(cx: float, cy: float, cyaw: float, p: VehicleParams, dt: float) -> tuple[float, float, float]:
    """The combine's pose (x m, y m, yaw rad, world) ``dt`` s on: exact for its constant speed and yaw rate (a
    straight line, or an arc of radius speed / yaw rate). Used where the tractor-cart is not integrated with it
    (an FMU vehicle); the built-in integrators take the combine rows of :func:`kinematic_derivative`."""
    vc, wc = p.combine_speed_mps, p.combine_yaw_rate_radps
    if wc == 0.0:
        return cx + vc * dt * math.cos(cyaw), cy + vc * dt * math.sin(cyaw), cyaw
    r, yaw = vc / wc, cyaw + wc * dt
    return cx + r * (math.sin(yaw) - math.sin(cyaw)), cy - r * (math.cos(yaw) - math.cos(cyaw)), yaw


def kinematic_derivative(k: list[float], v: float, delta: float, p: VehicleParams) -> tuple[float, ...]:
    """Time derivative of the seven kinematic states ``k`` = (cx, cy, cyaw, tx, ty, tyaw, pyaw) at the given
    wheel speed v (m/s; the ground speed is v times ``p.ground_keep``) and steering angle delta (rad)."""
    cyaw = k[2]
    vc = p.combine_speed_mps
    if p.ground_keep != 1.0:                          # wheel slip: the tractor moves at its ground speed
        v = v * p.ground_keep
    r = v * math.tan(delta) / p.wheelbase_m
    dp, vx, vy = towing_rates(v, r, k[5], k[6], p.hitch_offset_m, p.tow_length_m)
    return (vc * math.cos(cyaw), vc * math.sin(cyaw), p.combine_yaw_rate_radps, vx, vy, r, dp)


def derivative(x: np.ndarray, u: tuple[float, float], p: VehicleParams) -> np.ndarray:
    """dx/dt (9,) float64 for state ``x`` (9,) and held input ``u`` = (v_cmd m/s, delta_cmd rad)."""
    xs = x.tolist()
    v, d = xs[V], xs[DELTA]
    k = kinematic_derivative([xs[0], xs[1], xs[2], xs[3], xs[4], xs[5], xs[8]], v, d, p)
    dv = _clip((u[0] - v) / p.drivetrain_tau_s, -p.brake_max_mps2, p.accel_max_mps2)
    dd = _clip((u[1] - d) / p.steer_tau_s, -p.steer_rate_max_radps, p.steer_rate_max_radps)
    return np.array([k[0], k[1], k[2], k[3], k[4], k[5], dv, dd, k[6]])


def _lag_phases(x0: float, target: float, tau: float, rate_up: float, rate_down: float):
    """(e0, sign, limiting rate, band = tau * rate, end of the rate-limited ramp t1 or None) of a lag."""
    e0 = target - x0
    rate = rate_up if e0 >= 0.0 else rate_down
    sign = 1.0 if e0 >= 0.0 else -1.0
    band = tau * rate
    return e0, sign, rate, band, (abs(e0) - band) / rate if abs(e0) > band else None


def lag_exact(x0: float, target: float, tau: float, rate_up: float, rate_down: float, t: float) -> float:
    """Exact solution at time ``t`` >= 0 of dx/dt = clip((target - x) / tau, -rate_down, rate_up), x(0) = x0.

    While |target - x| > tau * rate the state ramps at the limiting rate; from then on it decays as
    exp(-t / tau). Same units as x; ``tau`` s, rates in units of x per s.
    """
    return _lag_at(_lag_phases(x0, target, tau, rate_up, rate_down), x0, target, tau, t)


def lag_exact_pair(x0: float, target: float, tau: float, rate_up: float, rate_down: float, t_a: float,
                   t_b: float) -> tuple[float, float]:
    """:func:`lag_exact` at two times ``t_a``, ``t_b`` (s) of one lag, its phases computed once."""
    ph = _lag_phases(x0, target, tau, rate_up, rate_down)
    return _lag_at(ph, x0, target, tau, t_a), _lag_at(ph, x0, target, tau, t_b)


def _lag_at(phases: tuple, x0: float, target: float, tau: float, t: float) -> float:
    """The lag's value at time ``t`` s from its :func:`_lag_phases`."""
    e0, sign, rate, band, t1 = phases
    if t1 is not None:
        if t <= t1:
            return x0 + sign * rate * t
        return target - sign * band * math.exp(-(t - t1) / tau)
    return target - e0 * math.exp(-t / tau)


def lag_integral(x0: float, target: float, tau: float, rate_up: float, rate_down: float, t: float) -> float:
    """Exact integral over [0, t] of the :func:`lag_exact` solution (units of x times s)."""
    e0, sign, rate, band, t1 = _lag_phases(x0, target, tau, rate_up, rate_down)
    if t1 is not None:
        if t <= t1:
            return x0 * t + 0.5 * sign * rate * t * t
        i1 = x0 * t1 + 0.5 * sign * rate * t1 * t1
        return i1 + target * (t - t1) - sign * band * tau * -math.expm1(-(t - t1) / tau)
    return target * t - e0 * tau * -math.expm1(-t / tau)


def tractor_pose(x: np.ndarray, p: VehicleParams) -> tuple[float, float, float]:
    """Tractor body origin (x m, y m, yaw rad), world: the rear axle moved forward by -rear_axle_x_m."""
    yaw = float(x[TYAW])
    return (float(x[TX]) - p.rear_axle_x_m * math.cos(yaw), float(x[TY]) - p.rear_axle_x_m * math.sin(yaw), yaw)


def hitch_point(x: np.ndarray, p: VehicleParams) -> tuple[float, float]:
    """Hitch (x m, y m), world: ``hitch_offset_m`` behind the tractor's rear axle."""
    yaw = float(x[TYAW])
    return (float(x[TX]) - p.hitch_offset_m * math.cos(yaw), float(x[TY]) - p.hitch_offset_m * math.sin(yaw))


def cart_pose(x: np.ndarray, p: VehicleParams) -> tuple[float, float, float]:
    """Cart body origin (x m, y m, yaw rad), world: ``tow_length_m`` behind the hitch along the cart heading."""
    hx, hy = hitch_point(x, p)
    yaw = float(x[PYAW])
    return (hx - p.tow_length_m * math.cos(yaw), hy - p.tow_length_m * math.sin(yaw), yaw)


def initial_state(s: Scenario, p: VehicleParams | None = None) -> np.ndarray:
    """State (9,) at t = 0: combine at its start pose and speed; tractor aligned with it at the Machine Sync
    setpoint plus ``initial_*_error_m``, at combine speed, wheels straight; cart straight behind."""
    p = p or VehicleParams.from_scenario(s)
    cx, cy = s.combine.start_xy_m
    yaw = math.radians(s.combine.heading_deg)
    ms = s.machine_sync
    # tractor rear axle offset in combine axes when the cart sits exactly at the setpoint
    ax = ms.longitudinal_offset_m + p.tow_length_m + p.hitch_offset_m + ms.initial_long_error_m
    ay = ms.lateral_offset_m + ms.initial_lat_error_m
    c, sn = math.cos(yaw), math.sin(yaw)
    x = np.zeros(N_STATES)
    x[CX], x[CY], x[CYAW] = cx, cy, yaw
    x[TX], x[TY], x[TYAW] = cx + c * ax - sn * ay, cy + sn * ax + c * ay, yaw
    x[V] = p.combine_speed_mps
    x[PYAW] = yaw
    return x
