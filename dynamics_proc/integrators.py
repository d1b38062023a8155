"""Integration of the vehicle state over one held-input step (selectable method).

* ``rk4``: classic fixed-step Runge-Kutta 4 on the full state. Stable only while dt is not much larger than
  the lag time constants (dt / tau < 2.78 in the linear range); the rate limits keep it bounded beyond.
* ``exponential``: the two lag states are advanced by their exact solution (rate limits included,
  :func:`~dynamics_proc.vehicles.lag_exact`), and the kinematic states by RK4 with the lag states taken from
  that exact solution at the stage times, or, where the step does not resolve a lag (dt > tau), its exact
  means over the stage intervals (so the distance travelled stays exact). Unconditionally stable for any tau.
* ``radau`` / ``bdf``: scipy ``solve_ivp`` (implicit, adaptive) with the given tolerances: the reference.

Every function maps state (9,) float64 -> new state (9,) float64 over ``dt`` seconds; inputs are held.
"""
from __future__ import annotations

import math
from typing import Literal

import numpy as np

from .vehicles import DELTA, V, VehicleParams, derivative, lag_exact, lag_exact_pair, lag_integral

__all__ = ["METHODS", "step_rk4", "step_exponential", "step_exponential_values", "step_ivp", "integrate"]

METHODS = ("rk4", "exponential", "radau", "bdf")


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


def _rates(cyaw: float, tyaw: float, pyaw: float, v: float, delta: float,
           p: VehicleParams) -> tuple[float, float, float, float, float, float]:
    """The kinematic derivatives that vary, (d cx, d cy, d tx, d ty, d tyaw, d pyaw) in m/s and rad/s: the
    arithmetic of :func:`~dynamics_proc.vehicles.kinematic_derivative`, without the constant combine yaw rate
    and without the positions, which no derivative depends on."""
    vc = p.combine_speed_mps
    r = v * math.tan(delta) / p.wheelbase_m
    rel = tyaw - pyaw
    dp = (v * math.sin(rel) - p.hitch_offset_m * r * math.cos(rel)) / p.tow_length_m
    return vc * math.cos(cyaw), vc * math.sin(cyaw), v * math.cos(tyaw), v * math.sin(tyaw), r, dp


def step_exponential_values(xs: list[float], u: tuple[float, float], p: VehicleParams, dt: float) -> list[float]:
    """:func:`step_exponential` on the state as a list of 9 Python floats (same order, same arithmetic, so the
    same bits): the frame loop keeps the state as floats between its held-input steps."""
    v0, vm, v1, v_end = _stage_lag(xs[V], u[0], p.drivetrain_tau_s, p.accel_max_mps2, p.brake_max_mps2, dt)
    r = p.steer_rate_max_radps
    d0, dm, d1, d_end = _stage_lag(xs[DELTA], u[1], p.steer_tau_s, r, r, dt)
    cx, cy, cyaw, tx, ty, tyaw, pyaw = xs[0], xs[1], xs[2], xs[3], xs[4], xs[5], xs[8]
    wc = p.combine_yaw_rate_radps
    half = 0.5 * dt
    # RK4 stages; only the headings feed back into the derivatives (k = d cx, cy, tx, ty, tyaw, pyaw)
    k1 = _rates(cyaw, tyaw, pyaw, v0, d0, p)
    k2 = _rates(cyaw + half * wc, tyaw + half * k1[4], pyaw + half * k1[5], vm, dm, p)
    k3 = _rates(cyaw + half * wc, tyaw + half * k2[4], pyaw + half * k2[5], vm, dm, p)
    k4 = _rates(cyaw + dt * wc, tyaw + dt * k3[4], pyaw + dt * k3[5], v1, d1, p)
    w = dt / 6.0
    return [cx + w * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0]), cy + w * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1]),
            cyaw + w * (wc + 2.0 * wc + 2.0 * wc + wc), tx + w * (k1[2] + 2.0 * k2[2] + 2.0 * k3[2] + k4[2]),
            ty + w * (k1[3] + 2.0 * k2[3] + 2.0 * k3[3] + k4[3]), tyaw + w * (k1[4] + 2.0 * k2[4] + 2.0 * k3[4] + k4[4]),
            v_end, d_end, pyaw + w * (k1[5] + 2.0 * k2[5] + 2.0 * k3[5] + k4[5])]


def step_ivp(x: np.ndarray, u: tuple[float, float], p: VehicleParams, dt: float,
             method: Literal["radau", "bdf"] = "radau", rtol: float = 1e-8, atol: float = 1e-10) -> np.ndarray:
    """One step of ``dt`` s with scipy ``solve_ivp`` (``Radau`` or ``BDF``). Raises RuntimeError on failure."""
    from scipy.integrate import solve_ivp   # only the reference methods need scipy (~0.3 s to import)

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
