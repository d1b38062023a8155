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

from typing import Literal

import numpy as np
from scipy.integrate import solve_ivp

from .vehicles import DELTA, V, VehicleParams, derivative, kinematic_derivative, lag_exact, lag_integral

__all__ = ["METHODS", "step_rk4", "step_exponential", "step_ivp", "integrate"]

METHODS = ("rk4", "exponential", "radau", "bdf")
_KIN = (0, 1, 2, 3, 4, 5, 8)     # kinematic states, in kinematic_derivative's order


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
    end = lag_exact(x0, target, tau, up, down, dt)
    if dt <= tau:
        return x0, lag_exact(x0, target, tau, up, down, 0.5 * dt), end, end
    i_half = lag_integral(x0, target, tau, up, down, 0.5 * dt)
    i_full = lag_integral(x0, target, tau, up, down, dt)
    return 2.0 * i_half / dt, i_full / dt, 2.0 * (i_full - i_half) / dt, end


def step_exponential(x: np.ndarray, u: tuple[float, float], p: VehicleParams, dt: float) -> np.ndarray:
    """Exact lags, RK4 kinematics driven by them; one step of ``dt`` s."""
    xs = x.tolist()
    v0, vm, v1, v_end = _stage_lag(xs[V], u[0], p.drivetrain_tau_s, p.accel_max_mps2, p.brake_max_mps2, dt)
    r = p.steer_rate_max_radps
    d0, dm, d1, d_end = _stage_lag(xs[DELTA], u[1], p.steer_tau_s, r, r, dt)
    y0 = [xs[i] for i in _KIN]
    k1 = kinematic_derivative(y0, v0, d0, p)
    k2 = kinematic_derivative([a + 0.5 * dt * b for a, b in zip(y0, k1)], vm, dm, p)
    k3 = kinematic_derivative([a + 0.5 * dt * b for a, b in zip(y0, k2)], vm, dm, p)
    k4 = kinematic_derivative([a + dt * b for a, b in zip(y0, k3)], v1, d1, p)
    y1 = [a + (dt / 6.0) * (b + 2.0 * c + 2.0 * d + e) for a, b, c, d, e in zip(y0, k1, k2, k3, k4)]
    return np.array([y1[0], y1[1], y1[2], y1[3], y1[4], y1[5], v_end, d_end, y1[6]])


def step_ivp(x: np.ndarray, u: tuple[float, float], p: VehicleParams, dt: float,
             method: Literal["radau", "bdf"] = "radau", rtol: float = 1e-8, atol: float = 1e-10) -> np.ndarray:
    """One step of ``dt`` s with scipy ``solve_ivp`` (``Radau`` or ``BDF``). Raises RuntimeError on failure."""
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
