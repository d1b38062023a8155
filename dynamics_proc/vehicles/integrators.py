"""Integration of the vehicle state over one held-input step (selectable method).

* ``rk4``: classic fixed-step Runge-Kutta 4 on the full state. Stable only while dt is not much larger than
  the lag time constants (dt / tau < 2.78 in the linear range); the rate limits keep it bounded beyond.
* ``exponential``: the two lag states are advanced by their exact solution (rate limits included,
  :func:`~dynamics_proc.vehicles.motion.lag_exact`), and the kinematic states by RK4 with the lag states taken from
  that exact solution at the stage times, or, where the step does not resolve a lag (dt > tau), its exact
  means over the stage intervals (so the distance travelled stays exact). Unconditionally stable for any tau.
* ``radau`` / ``bdf``: scipy ``solve_ivp`` (implicit, adaptive) with the given tolerances: the reference.

Every function maps state (9,) float64 -> new state (9,) float64 over ``dt`` seconds; inputs are held.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from dynamics_proc.vehicles.motion import (
    DELTA,
    V,
    VehicleParams,
    derivative,
    lag_exact,
    lag_exact_pair,
    lag_integral,
    towing_rates,
)

__all__ = ["METHODS", "Stepping", "step_rk4", "step_exponential", "step_exponential_values", "step_ivp", "integrate"]

METHODS = ("rk4", "exponential", "radau", "bdf")


@dataclass(frozen=True)
class Stepping:
    """How the vehicle state is integrated over a frame: ``steps`` held-input steps of ``dt_s`` s by ``method``
    (:data:`METHODS`), with the tolerances ``rtol`` / ``atol`` of the scipy methods."""

    method: str
    dt_s: float
    steps: int
    rtol: float
    atol: float


def step_rk4(x: np.ndarray, u: tuple[float, float], p: VehicleParams, dt: float) -> np.ndarray:
    """One classic RK4 step of length ``dt`` s."""
    k1 = derivative(x, u, p)
    k2 = derivative(x + 0.5 * dt * k1, u, p)
    k3 = derivative(x + 0.5 * dt * k2, u, p)
    k4 = derivative(x + dt * k3, u, p)
    return x + (dt / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


def _stage_lag(x0: float, target: float, tau: float, up: float, down: float, dt: float) -> tuple[float, ...]:
    """Lag values for the RK4 stages at 0, dt/2, dt, and the end value. When dt resolves the lag (dt <= tau)
    these are the exact point values. When it does not (stiff), the transient falls between the stage times,
    so the stages take the exact means over [0, dt/2], [0, dt] and [dt/2, dt] instead: with Simpson's
    weights that reproduces the exact integral of the lag state (the distance travelled) over the step."""
    if dt <= tau:
        mid, end = lag_exact_pair(x0, target, tau, up, down, 0.5 * dt, dt)
        return x0, mid, end, end
    end = lag_exact(x0, target, tau, up, down, dt)
    i_half = lag_integral(x0, target, tau, up, down, 0.5 * dt)
    i_full = lag_integral(x0, target, tau, up, down, dt)
    return 2.0 * i_half / dt, i_full / dt, 2.0 * (i_full - i_half) / dt, end


def step_exponential(x: np.ndarray, u: tuple[float, float], p: VehicleParams, dt: float) -> np.ndarray:
    """Exact lags, RK4 kinematics driven by them; one step of ``dt`` s."""
    return np.array(step_exponential_values(x.tolist(), u, p, dt))


def step_exponential_values(xs: list[float], u: tuple[float, float], p: VehicleParams, dt: float) -> list[float]:
    """:func:`step_exponential` on the state as a list of 9 Python floats (same order, same arithmetic, so the
    same bits): the frame loop keeps the state as floats between its held-input steps.

    The RK4 stages evaluate :func:`~dynamics_proc.vehicles.motion.kinematic_derivative` inline (its combine rows here,
    its tractor-and-cart rows through :func:`~dynamics_proc.vehicles.motion.towing_rates`); only the headings feed
    back into the derivatives, so the stage positions are not formed, and stages 2 and 3 share the combine
    heading (its yaw rate is constant)."""
    v0, vm, v1, v_end = _stage_lag(xs[V], u[0], p.drivetrain_tau_s, p.accel_max_mps2, p.brake_max_mps2, dt)
    if p.ground_keep != 1.0:                      # wheel slip: the kinematics move at the ground speed
        v0, vm, v1 = v0 * p.ground_keep, vm * p.ground_keep, v1 * p.ground_keep
    r = p.steer_rate_max_radps
    d0, dm, d1, d_end = _stage_lag(xs[DELTA], u[1], p.steer_tau_s, r, r, dt)
    cx, cy, cyaw, tx, ty, tyaw, pyaw = xs[0], xs[1], xs[2], xs[3], xs[4], xs[5], xs[8]
    vc, wc, wb, hitch, tow = (p.combine_speed_mps, p.combine_yaw_rate_radps, p.wheelbase_m, p.hitch_offset_m,
                              p.tow_length_m)
    cos, sin, tan = math.cos, math.sin, math.tan
    half = 0.5 * dt
    # combine velocity at the stage headings cyaw, cyaw + dt/2 wc (stages 2 and 3), cyaw + dt wc
    c_mid, c_end = cyaw + half * wc, cyaw + dt * wc
    cx1, cy1 = vc * cos(cyaw), vc * sin(cyaw)
    cx2, cy2 = vc * cos(c_mid), vc * sin(c_mid)
    cx4, cy4 = vc * cos(c_end), vc * sin(c_end)
    # tractor and cart: speed v, yaw rate r = v tan(delta) / wheelbase, trailer rate dp, stage by stage
    r1 = v0 * tan(d0) / wb
    p1, tx1, ty1 = towing_rates(v0, r1, tyaw, pyaw, hitch, tow)
    t2, q2 = tyaw + half * r1, pyaw + half * p1
    r2 = vm * tan(dm) / wb
    p2, tx2, ty2 = towing_rates(vm, r2, t2, q2, hitch, tow)
    t3, q3 = tyaw + half * r2, pyaw + half * p2
    r3 = r2                                        # same speed and steering as stage 2
    p3, tx3, ty3 = towing_rates(vm, r3, t3, q3, hitch, tow)
    t4, q4 = tyaw + dt * r3, pyaw + dt * p3
    r4 = v1 * tan(d1) / wb
    p4, tx4, ty4 = towing_rates(v1, r4, t4, q4, hitch, tow)
    w = dt / 6.0
    return [cx + w * (cx1 + 2.0 * cx2 + 2.0 * cx2 + cx4), cy + w * (cy1 + 2.0 * cy2 + 2.0 * cy2 + cy4),
            cyaw + w * (wc + 2.0 * wc + 2.0 * wc + wc), tx + w * (tx1 + 2.0 * tx2 + 2.0 * tx3 + tx4),
            ty + w * (ty1 + 2.0 * ty2 + 2.0 * ty3 + ty4), tyaw + w * (r1 + 2.0 * r2 + 2.0 * r3 + r4), v_end, d_end,
            pyaw + w * (p1 + 2.0 * p2 + 2.0 * p3 + p4)]


def step_ivp(x: np.ndarray, u: tuple[float, float], p: VehicleParams, dt: float,
             method: Literal["radau", "bdf"] = "radau", rtol: float = 1e-8, atol: float = 1e-10) -> np.ndarray:
    """One step of ``dt`` s with scipy ``solve_ivp`` (``Radau`` or ``BDF``). Raises RuntimeError on failure."""
    from scipy.integrate import solve_ivp  # only the reference methods need scipy (~0.3 s to import)

    sol = solve_ivp(lambda _t, y: derivative(y, u, p), (0.0, dt), x, method="Radau" if method == "radau" else "BDF",
                    rtol=rtol, atol=atol)
    if not sol.success:
        raise RuntimeError(f"solve_ivp ({method}) failed over dt = {dt} s: {sol.message}")
    return sol.y[:, -1].copy()


def integrate(method: str, x: np.ndarray, u: tuple[float, float], p: VehicleParams, dt: float,
              substeps: int = 1, rtol: float = 1e-8, atol: float = 1e-10) -> np.ndarray:
    """Advance ``x`` over ``dt`` s with input ``u`` held, in ``substeps`` equal steps of ``method``."""
    if method not in METHODS:
        raise ValueError(f"unknown integration method {method!r}; choose one of {METHODS}")
    if substeps < 1:
        raise ValueError(f"substeps must be >= 1, got {substeps}")
    h = dt / substeps
    if method in ("radau", "bdf"):
        return step_ivp(x, u, p, dt, method, rtol, atol)
    f = step_rk4 if method == "rk4" else step_exponential
    for _ in range(substeps):
        x = f(x, u, p, h)
    return x
