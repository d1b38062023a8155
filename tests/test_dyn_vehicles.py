"""Vehicles, lags, integrators and Machine Sync against closed forms and independent references."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp
from scipy.linalg import expm

from cosim.scenario.config import Scenario
from dynamics_proc.vehicles.integrators import integrate, step_exponential, step_exponential_values, step_ivp
from dynamics_proc.vehicles.machine_sync import cart_offset, sync_command, tractor_offset
from dynamics_proc.vehicles.motion import (
    CX,
    CY,
    DELTA,
    PYAW,
    TX,
    TY,
    TYAW,
    V,
    VehicleParams,
    cart_pose,
    combine_advance,
    initial_state,
    kinematic_derivative,
    lag_exact,
    lag_integral,
)


def scen(**kw) -> Scenario:
    d = {"format_version": 1, "feedback": "ground_truth", "renderer": "none"}
    d.update(kw)
    return Scenario.model_validate(d)


def run_sync(s: Scenario, seconds: float, dt: float, method: str = "exponential", setpoint=None):
    """Vehicles under Machine Sync alone (no grain), held input per step: states (n + 1, 9)."""
    p = VehicleParams.from_scenario(s)
    from dynamics_proc.vehicles.machine_sync import SyncGains
    g = SyncGains.from_scenario(s)
    sp = setpoint or (s.machine_sync.longitudinal_offset_m, s.machine_sync.lateral_offset_m)
    x = initial_state(s, p)
    out = [x]
    for _ in range(round(seconds / dt)):
        x = integrate(method, x, sync_command(x, sp, p, g), p, dt)
        out.append(x)
    return np.array(out), p


# -- lags -----------------------------------------------------------------------------------------------
def test_lag_unsaturated_is_exponential():
    t = np.linspace(0.0, 3.0, 31)
    got = [lag_exact(0.0, 0.1, 0.5, 1.0, 3.0, float(ti)) for ti in t]
    np.testing.assert_allclose(got, 0.1 * (1.0 - np.exp(-t / 0.5)), rtol=0, atol=1e-15)


def test_lag_saturated_ramps_then_decays():
    # |e0| = 2 > tau * rate = 0.5: ramp at 1 m/s^2 for 1.5 s, then exponential from e = 0.5
    assert lag_exact(0.0, 2.0, 0.5, 1.0, 3.0, 1.0) == pytest.approx(1.0, abs=1e-15)
    assert lag_exact(0.0, 2.0, 0.5, 1.0, 3.0, 2.0) == pytest.approx(2.0 - 0.5 * math.exp(-1.0), abs=1e-15)
    # braking uses the braking limit: 3 m/s^2 down from 4 towards 0, band 1.5
    assert lag_exact(4.0, 0.0, 0.5, 1.0, 3.0, 0.5) == pytest.approx(2.5, abs=1e-15)


@settings(max_examples=25, deadline=None)
@given(x0=st.floats(-5, 5), target=st.floats(-5, 5), tau=st.floats(1e-3, 2.0), up=st.floats(0.1, 5.0),
       down=st.floats(0.1, 5.0), t=st.floats(0.0, 4.0))
def test_lag_exact_matches_radau(x0, target, tau, up, down, t):
    def f(_t, y):
        return [min(max((target - y[0]) / tau, -down), up)]
    ref = solve_ivp(f, (0.0, max(t, 1e-12)), [x0], method="Radau", rtol=1e-11, atol=1e-12).y[0, -1]
    assert lag_exact(x0, target, tau, up, down, t) == pytest.approx(ref, abs=2e-7 * (1 + abs(target - x0)))


@settings(max_examples=25, deadline=None)
@given(x0=st.floats(-5, 5), target=st.floats(-5, 5), tau=st.floats(1e-3, 2.0), up=st.floats(0.1, 5.0),
       down=st.floats(0.1, 5.0), t=st.floats(0.0, 4.0))
def test_lag_integral_matches_quadrature(x0, target, tau, up, down, t):
    from scipy.integrate import quad
    e0 = abs(target - x0)
    kink = max(0.0, (e0 - tau * (up if target >= x0 else down)) / (up if target >= x0 else down))
    ref = quad(lambda s: lag_exact(x0, target, tau, up, down, s), 0.0, t,
               points=[kink] if 0.0 < kink < t else None, epsabs=1e-12, epsrel=1e-12, limit=200)[0]
    assert lag_integral(x0, target, tau, up, down, t) == pytest.approx(ref, abs=1e-9 * (1 + abs(ref)))


def test_exponential_keeps_the_stiff_distance_exact():
    """tau = 1 ms, one 0.1 s step on a straight line: the distance is the exact integral of the lag; RK4's
    point samples of the speed miss the 1 ms transient."""
    s = scen(tractor={"drivetrain_tau_s": 0.001, "accel_max_mps2": 100.0})
    p = VehicleParams.from_scenario(s)
    x = initial_state(s, p)
    u = (3.0, 0.0)
    exact = lag_integral(2.0, 3.0, 0.001, 100.0, 3.0, 0.1)
    t1 = (1.0 - 0.1) / 100.0                  # ramp at 100 m/s^2 until within tau * a = 0.1 m/s, then decay
    closed = 2.0 * t1 + 50.0 * t1 ** 2 + 3.0 * (0.1 - t1) - 0.1 * 0.001 * (1.0 - math.exp(-(0.1 - t1) / 0.001))
    assert exact == pytest.approx(closed, abs=1e-15)
    got = integrate("exponential", x, u, p, 0.1)[TX] - x[TX]
    assert got == pytest.approx(exact, abs=1e-12)
    rk = integrate("rk4", x, u, p, 0.1)[TX] - x[TX]
    assert abs(rk - exact) > 1e-3


def _exponential_step_reference(x, u, p, dt):
    """The exponential step written plainly from kinematic_derivative (the frame loop's inlined arithmetic must
    give these bits)."""
    from dynamics_proc.vehicles.integrators import _stage_lag
    v0, vm, v1, v_end = _stage_lag(x[V], u[0], p.drivetrain_tau_s, p.accel_max_mps2, p.brake_max_mps2, dt)
    r = p.steer_rate_max_radps
    d0, dm, d1, d_end = _stage_lag(x[DELTA], u[1], p.steer_tau_s, r, r, dt)
    y0 = [x[i] for i in (0, 1, 2, 3, 4, 5, 8)]
    k1 = kinematic_derivative(y0, v0, d0, p)
    k2 = kinematic_derivative([a + 0.5 * dt * b for a, b in zip(y0, k1)], vm, dm, p)
    k3 = kinematic_derivative([a + 0.5 * dt * b for a, b in zip(y0, k2)], vm, dm, p)
    k4 = kinematic_derivative([a + dt * b for a, b in zip(y0, k3)], v1, d1, p)
    y1 = [a + (dt / 6.0) * (b + 2.0 * c + 2.0 * d + e) for a, b, c, d, e in zip(y0, k1, k2, k3, k4)]
    return [y1[0], y1[1], y1[2], y1[3], y1[4], y1[5], v_end, d_end, y1[6]]


@settings(max_examples=200, deadline=None)
@given(state=st.lists(st.floats(-3.0, 3.0), min_size=9, max_size=9), v_cmd=st.floats(0.0, 6.0),
       d_cmd=st.floats(-0.6, 0.6), dt=st.sampled_from([0.002, 0.01, 0.1]), tau=st.sampled_from([0.001, 0.5]),
       radius=st.sampled_from([None, 60.0]))
def test_exponential_step_is_bit_identical_to_its_plain_form(state, v_cmd, d_cmd, dt, tau, radius):
    combine = {"path": "arc", "path_radius_m": radius} if radius else {}
    p = VehicleParams.from_scenario(scen(tractor={"drivetrain_tau_s": tau}, combine=combine))
    got = step_exponential_values(list(state), (v_cmd, d_cmd), p, dt)
    assert got == _exponential_step_reference(state, (v_cmd, d_cmd), p, dt)
    assert step_exponential(np.array(state), (v_cmd, d_cmd), p, dt).tolist() == got


@pytest.mark.parametrize("method,tol", [("rk4", 1e-9), ("exponential", 1e-14), ("radau", 1e-7), ("bdf", 1e-6)])
def test_drivetrain_step_response_each_method(method, tol):
    s = scen()
    p = VehicleParams.from_scenario(s)
    x = initial_state(s, p)
    u = (2.2, 0.0)                           # +0.2 m/s: 0.4 m/s^2 < accel limit, unsaturated
    t, dt = 0.0, 0.01
    for _ in range(100):
        x = integrate(method, x, u, p, dt)
        t += dt
    assert x[V] == pytest.approx(2.2 - 0.2 * math.exp(-t / p.drivetrain_tau_s), abs=tol)
    # position: integral of v, closed form
    dist = 2.2 * t - 0.2 * p.drivetrain_tau_s * (1 - math.exp(-t / p.drivetrain_tau_s))
    assert x[TX] - initial_state(s, p)[TX] == pytest.approx(dist, abs=max(tol, 1e-9) * 10)


def test_steering_lag_rate_limited():
    s = scen()
    p = VehicleParams.from_scenario(s)
    x = initial_state(s, p)
    x[V] = 0.0                                 # standing still: only the steering moves
    u = (0.0, p.steer_max_rad)                # 35 deg step: rate limit 30 deg/s binds first
    x1 = integrate("exponential", x, u, p, 0.5)
    assert x1[DELTA] == pytest.approx(0.5 * p.steer_rate_max_radps, abs=1e-15)
    x2 = integrate("rk4", x, u, p, 0.5, substeps=50)
    assert x2[DELTA] == pytest.approx(x1[DELTA], abs=1e-12)


def test_rk4_fourth_order():
    s = scen(tractor={"drivetrain_tau_s": 0.5})
    p = VehicleParams.from_scenario(s)
    x = initial_state(s, p)
    x[TYAW] = 0.3                              # a turning, accelerating transient, limits not reached (the
    u = (2.2, 0.05)                            # clipped derivative has kinks that cost the order)
    ref = step_ivp(x, u, p, 1.0, "radau", rtol=1e-12, atol=1e-13)
    e = [np.abs(integrate("rk4", x, u, p, 1.0, substeps=n) - ref).max() for n in (20, 40)]
    assert e[0] / e[1] > 12.0                  # ~16 for 4th order


# -- Machine Sync -----------------------------------------------------------------------------------------
def test_longitudinal_response_matches_second_order_closed_form():
    """tau e'' + e' + kp e = 0 along a straight path (small step: no limits, no steering)."""
    s = scen(machine_sync={"initial_long_error_m": -0.2})
    states, p = run_sync(s, 12.0, 0.001)
    sp = (s.machine_sync.longitudinal_offset_m, s.machine_sync.lateral_offset_m)
    e = np.array([sp[0] - cart_offset(x, p)[0] for x in states])
    kp, tau = s.machine_sync.kp_long, p.drivetrain_tau_s
    a = np.array([[0.0, 1.0], [-kp / tau, -1.0 / tau]])      # state (e, e')
    t = np.arange(len(e)) * 0.001
    ref = np.array([(expm(a * ti) @ np.array([0.2, 0.0]))[0] for ti in t[::100]])
    np.testing.assert_allclose(e[::100], ref, atol=2e-4)
    zeta = 1.0 / (2.0 * math.sqrt(tau * kp))                 # 0.79 for the defaults: underdamped
    assert e.min() == pytest.approx(-0.2 * math.exp(-math.pi * zeta / math.sqrt(1 - zeta ** 2)), rel=0.02)
    assert abs(e[-1]) < 1e-5


def test_straight_steady_state_offsets_zero():
    s = scen(machine_sync={"initial_long_error_m": 0.5, "initial_lat_error_m": -0.4})
    states, p = run_sync(s, 40.0, 0.01)
    long_m, lat_m = cart_offset(states[-1], p)
    assert long_m == pytest.approx(s.machine_sync.longitudinal_offset_m, abs=1e-4)
    assert lat_m == pytest.approx(s.machine_sync.lateral_offset_m, abs=1e-4)
    assert states[-1][V] == pytest.approx(2.0, abs=1e-6)


def test_arc_steady_state_trailer_offtracking_closed_form():
    """On a circle the tractor holds its setpoint; the cart axle runs on sqrt(R_t^2 + h^2 - L^2)."""
    s = scen(combine={"path": "arc", "path_radius_m": 60.0})
    states, p = run_sync(s, 90.0, 0.01)
    x = states[-1]
    centre = (x[CX] - 60.0 * math.sin(x[2]), x[CY] + 60.0 * math.cos(x[2]))
    r_t = math.hypot(x[TX] - centre[0], x[TY] - centre[1])
    cx, cy, _ = cart_pose(x, p)
    r_c = math.hypot(cx - centre[0], cy - centre[1])
    assert r_c == pytest.approx(math.sqrt(r_t ** 2 + p.hitch_offset_m ** 2 - p.tow_length_m ** 2), abs=2e-3)
    ax, ay = tractor_offset((s.machine_sync.longitudinal_offset_m, s.machine_sync.lateral_offset_m), p)
    cyaw = x[2]
    dx, dy = x[TX] - x[CX], x[TY] - x[CY]
    assert math.cos(cyaw) * dx + math.sin(cyaw) * dy == pytest.approx(ax, abs=5e-3)
    assert -math.sin(cyaw) * dx + math.cos(cyaw) * dy == pytest.approx(ay, abs=5e-3)


# -- stiff and extreme -----------------------------------------------------------------------------------
@pytest.mark.parametrize("method", ["rk4", "exponential", "radau"])
def test_stiff_drivetrain_stays_finite_and_close(method):
    """tau = 1 ms with 10 ms steps (dt / tau = 10): beyond RK4's linear stability limit."""
    s = scen(tractor={"drivetrain_tau_s": 0.001}, machine_sync={"initial_long_error_m": -1.0})
    seconds = 2.0 if method == "radau" else 10.0             # covers the saturated catch-up; Radau is slow
    states, p = run_sync(s, seconds, 0.01, method)
    ref, _ = run_sync(s, seconds, 0.01, "exponential")
    assert np.all(np.isfinite(states))
    # RK4: its rate-limited derivative keeps it within one step of braking of the exact lag; Radau: the kink in
    # the clipped derivative limits its accuracy at rtol 1e-8
    tol = {"rk4": p.brake_max_mps2 * 0.01 * 1.01, "exponential": 1e-12, "radau": 1e-3}[method]
    assert np.abs(states[:, V] - ref[:, V]).max() <= tol
    assert np.abs(states[:, TX] - ref[:, TX]).max() <= 50 * tol


def test_zero_speed_stays_put():
    s = scen(combine={"speed_mps": 0.0}, machine_sync={"initial_long_error_m": 0.3, "initial_lat_error_m": 0.2})
    states, p = run_sync(s, 20.0, 0.01)
    assert np.all(np.isfinite(states))
    assert abs(states[-1][V]) < 1e-6 and np.abs(states[:, DELTA]).max() <= p.steer_max_rad + 1e-12
    assert np.abs(states[:, PYAW]).max() < 0.2


def test_combine_advance_is_the_exact_arc_and_line():
    """combine_advance (the FMU vehicle's combine): 1000 steps of 10 ms land on the closed-form circle / line."""
    p = VehicleParams.from_scenario(Scenario.model_validate({"format_version": 1, "combine": {"path": "arc",
                                                             "path_radius_m": 50.0, "speed_mps": 2.5}}))
    x, y, yaw = 3.0, -1.0, 0.4
    for _ in range(1000):
        x, y, yaw = combine_advance(x, y, yaw, p, 0.01)
    r, w = 50.0, 2.5 / 50.0
    cx, cy = 3.0 - r * math.sin(0.4), -1.0 + r * math.cos(0.4)      # centre, to the left
    assert yaw == pytest.approx(0.4 + 10.0 * w, abs=1e-12)
    assert (x, y) == pytest.approx((cx + r * math.sin(yaw), cy - r * math.cos(yaw)), abs=1e-9)
    line = dataclasses.replace(p, combine_yaw_rate_radps=0.0)
    assert combine_advance(3.0, -1.0, 0.4, line, 2.0) == pytest.approx(
        (3.0 + 5.0 * math.cos(0.4), -1.0 + 5.0 * math.sin(0.4), 0.4), abs=1e-12)
