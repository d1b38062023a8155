"""Machine Sync and the flow in a field (dynamics_proc.vehicles.fieldnoise, dynamics_proc.vehicles.fieldsync): the GNSS error's
variance and correlation time, latency, actuation delay, slip, the speed and turn profile, the flow's variation,
the controller's guards through a stop and a start, determinism."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from cosim.runtime.outcome import judge
from cosim.scenario.config import Scenario
from dynamics_proc.closed_loop import simulate
from dynamics_proc.summary import summarize
from dynamics_proc.vehicles.fieldnoise import gm_coefficients, gm_series
from dynamics_proc.vehicles.fieldsync import FieldParams, combine_motion, speed_change
from dynamics_proc.vehicles.motion import VehicleParams

STOP_GO = [{"t_s": 0, "speed_mps": 2}, {"t_s": 20, "speed_mps": 2}, {"t_s": 22, "speed_mps": 0},
           {"t_s": 30, "speed_mps": 0}, {"t_s": 32, "speed_mps": 2}]


def scen(**kw) -> Scenario:
    d = {"format_version": 1, "feedback": "ground_truth", "renderer": "none", "duration_s": 120.0}
    d.update(kw)
    return Scenario.model_validate_json(json.dumps(d))


def _outcome(s, r) -> dict:
    return judge(s, {**summarize(s, r.series, r.heights), "completed": True}, r.series)


def test_the_gauss_markov_process_has_its_variance_and_correlation_time():
    sigma, tau, dt = 0.02, 3.0, 0.1
    x = np.concatenate([gm_series(sigma, tau, dt, 4000, seed) for seed in range(6)])
    assert np.var(x) == pytest.approx(sigma ** 2, rel=0.1)
    lag = int(round(tau / dt))
    r = np.mean([np.corrcoef(s[:-lag], s[lag:])[0, 1] for s in np.split(x, 6)])
    assert r == pytest.approx(math.exp(-1.0), abs=0.06)
    assert gm_coefficients(sigma, tau, dt) == pytest.approx((math.exp(-dt / tau), sigma * math.sqrt(1 - math.exp(
        -2 * dt / tau))))
    assert np.array_equal(gm_series(sigma, tau, dt, 50, 7), gm_series(sigma, tau, dt, 50, 7))


def test_every_condition_at_its_default_is_no_field_at_all():
    assert FieldParams.from_scenario(scen()) is None
    r = simulate(scen(duration_s=5.0))
    assert r.world.field is None and not r.series["dyn_state.gnss_error_long_m"].any()


def test_the_profile_is_linear_between_its_points_and_its_steepest_change_is_known():
    s = scen(combine={"profile": [{"t_s": 10, "speed_mps": 2, "curvature_1pm": 0.0},
                                  {"t_s": 20, "speed_mps": 1, "curvature_1pm": 0.02}]})
    fp, vp = FieldParams.from_scenario(s), VehicleParams.from_scenario(s)
    assert combine_motion(fp, vp, 0.0) == (2.0, 0.0) and combine_motion(fp, vp, 99.0) == (1.0, 0.02)
    v, w = combine_motion(fp, vp, 15.0)
    assert v == pytest.approx(1.5) and w == pytest.approx(1.5 * 0.01)
    assert speed_change(fp, 0.0, 5.0) == 0.0 and speed_change(fp, 8.0, 5.0) == pytest.approx(0.1)


def test_slip_slows_the_tractor_over_the_ground_by_its_fraction():
    # the tractor on its own at a held wheel speed: distance over the ground = wheel speed x (1 - slip) x time
    from dataclasses import replace

    from dynamics_proc.vehicles.integrators import step_exponential_values
    vp = replace(VehicleParams.from_scenario(scen()), ground_keep=0.9)
    xs = [0.0] * 9
    xs[6] = 2.0
    for _ in range(100):
        xs = step_exponential_values(xs, (2.0, 0.0), vp, 0.01)
    assert xs[3] == pytest.approx(2.0 * 0.9 * 1.0, abs=1e-12)


def test_a_compensated_latency_on_a_steady_straight_path_changes_nothing():
    base, late = simulate(scen(duration_s=30.0)), simulate(scen(duration_s=30.0,
                                                                 machine_sync={"radio_latency_s": 0.3}))
    for k in ("dyn_state.cart_x_m", "dyn_state.cart_y_m", "dyn_state.delivered_m3"):
        assert late.series[k] == pytest.approx(base.series[k], abs=1e-9)
    uncompensated = simulate(scen(duration_s=30.0, machine_sync={"radio_latency_s": 0.3,
                                                                 "latency_compensation": False}))
    lag = uncompensated.series["dyn_state.offset_long_err_m"][120]            # steady between two nudges
    assert lag == pytest.approx(-2.0 * 0.3, abs=0.005)                       # the tractor lags speed x latency


def test_an_actuation_delay_delays_the_tractors_answer_by_that_long():
    s = scen(duration_s=3.0, machine_sync={"initial_long_error_m": 0.5, "actuation_delay_s": 0.5})
    r = simulate(s)
    v = r.series["dyn_state.tractor_speed_mps"]
    moved = np.flatnonzero(np.abs(v - v[0]) > 1e-9)
    assert r.series["dyn_state.t_s"][moved[0]] == pytest.approx(0.6)          # the first frame after 0.5 s
    r0 = simulate(scen(duration_s=3.0, machine_sync={"initial_long_error_m": 0.5}))
    assert np.abs(r0.series["dyn_state.tractor_speed_mps"][1] - v[0]) > 1e-3


def test_gnss_error_moves_the_tractor_and_the_controllers_view_with_its_statistics():
    s = scen(duration_s=60.0, machine_sync={"gnss": {"sigma": 0.02, "correlation_time_s": 30.0}})
    r = simulate(s)
    e = r.series["dyn_state.gnss_error_lat_m"]
    assert 0.005 < np.std(e) < 0.06 and np.abs(np.diff(e)).max() < 0.01      # relative error: slow, cm-sized
    again = simulate(s)
    assert all(np.array_equal(r.series[k], again.series[k], equal_nan=True) for k in r.series)
    assert _outcome(s, r)["status"] in ("filled", "unfinished", "job_failed")  # runs to the end either way


def test_the_controller_pauses_through_a_stop_and_a_start_instead_of_spilling():
    s = scen(combine={"profile": STOP_GO})
    r = simulate(s)
    assert r.series["dyn_state.spilled_m3"][-1] == 0.0 and _outcome(s, r)["status"] == "filled"
    blind = scen(combine={"profile": STOP_GO}, controller={"coping": {"pause_accel_mps2": 0.0, "safety_lead_s": 0.0}})
    assert simulate(blind).series["dyn_state.spilled_m3"][-1] > 0.01            # without the guards it spills


def test_the_flow_varies_with_the_yield_and_surges_at_each_start_and_the_balance_holds():
    s = scen(duration_s=40.0, auger={"flow_variation": {"sigma": 0.15, "correlation_time_s": 5.0},
                                     "start_surge": 0.5, "start_surge_tau_s": 1.0})
    r = simulate(s)
    f = r.series["dyn_state.flow_factor"]
    on = r.series["dyn_state.flow_level"] > 0.999
    assert 0.05 < np.std(f[on]) < 0.3
    start = np.flatnonzero(np.diff((r.series["dyn_state.flow_level"] > 0).astype(int)) == 1)[0] + 1
    assert f[start] > f[start + 30] + 0.3                                    # the surge at the start
    sm = summarize(s, r.series, r.heights)
    assert sm["mass_balance"]["relative_error"] <= 1e-12
