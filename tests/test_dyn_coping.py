"""The built-in controller copes (controller.coping; dynamics_proc.control.coping, dynamics_proc.control.feedforward): a lead on
the full level at high flow, dead reckoning and a safe hold when perception drops out, feed-forward through turns."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from cosim.cli import main
from cosim.runtime.outcome import HOLD_LOST, HOLD_NO_MEASUREMENT, judge
from cosim.scenario.config import Scenario
from cosim.scenario.loader import load_scenario, packaged_scenarios
from dynamics_proc.closed_loop import simulate
from dynamics_proc.control.coping import (
    MODE_DEAD_RECKONING,
    MODE_HOLD,
    MODE_MEASURED,
    SlowLimits,
    mode,
    rise_rate,
    slowed_section,
)
from dynamics_proc.control.feedforward import _spout_grid, steady_cart_offset, turn_compensation
from dynamics_proc.grain import auger as ag
from dynamics_proc.model import ModelParams
from dynamics_proc.summary import summarize
from dynamics_proc.vehicles.integrators import step_exponential_values
from dynamics_proc.vehicles.machine_sync import SyncGains, cart_offset, sync_command
from dynamics_proc.vehicles.motion import CYAW, VehicleParams, cart_pose, initial_state


def scen(**kw) -> Scenario:
    d = {"format_version": 1, "feedback": "ground_truth", "renderer": "none", "duration_s": 120.0}
    d.update(kw)
    return Scenario.model_validate(d)


def _outcome(s: Scenario, r) -> dict:
    sm = summarize(s, r.series, r.heights)
    return judge(s, {**sm, "completed": True}, r.series)


def test_the_rise_rate_filter_is_a_first_order_lag_of_the_true_rate():
    rate, h, dt, tau, r = np.zeros(1), np.zeros(1), 0.1, 2.0, 0.05
    for n in range(1, 31):
        rate = rise_rate(rate, h, h + r * dt, dt, tau)
        h = h + r * dt
        assert rate[0] == pytest.approx(r * (1.0 - (1.0 - dt / tau) ** n), rel=1e-12)
    assert rise_rate(rate, np.array([np.nan]), h, dt, tau)[0] == rate[0]         # unknown: kept


def test_slowing_starts_near_full_at_a_high_rise_only_and_lasts_until_the_impact_leaves():
    full, heights, centres = np.array([False, False, False]), np.array([1.80, 1.0, 1.0]), (1.0, 3.0, 5.0)
    args = dict(lead_s=1.0, allowance_m=0.06, full_level_m=1.89, centres_m=centres, section_m=2.0)
    assert slowed_section(0, -1, full, heights, np.array([0.10, 0, 0]), 1.0, SlowLimits(**args)) == 0     # 1.80 + 0.10
    assert slowed_section(0, -1, full, heights, np.array([0.05, 0, 0]), 1.0, SlowLimits(**args)) == -1    # rise <= allowance
    assert slowed_section(0, -1, full, np.array([1.7, 1, 1]), np.array([0.1, 0, 0]), 1.0, SlowLimits(**args)) == -1  # far
    done = np.array([True, False, False])
    assert slowed_section(1, 0, done, heights, np.zeros(3), 1.9, SlowLimits(**args)) == 0                 # still over 0
    assert slowed_section(1, 0, done, heights, np.zeros(3), 2.1, SlowLimits(**args)) == -1                # arrived
    assert slowed_section(1, 0, full, heights, np.zeros(3), 1.9, SlowLimits(**args)) == -1                # 0 left unfilled
    assert slowed_section(0, -1, full, heights, np.array([1.0, 0, 0]), 1.0, SlowLimits(**{**args, "lead_s": 0.0})) == -1


def test_modes_and_hold_reasons():
    assert mode(False, -1, False, True, math.nan, 0.05) == (MODE_HOLD, HOLD_NO_MEASUREMENT)
    assert mode(True, 3, True, True, 0.2, 0.05) == (MODE_MEASURED, 0)
    assert mode(True, 3, False, True, 0.04, 0.05) == (MODE_DEAD_RECKONING, 0)
    assert mode(True, 3, False, True, 0.06, 0.05) == (MODE_HOLD, HOLD_LOST)
    assert mode(True, 3, False, False, math.nan, 0.05) == (MODE_DEAD_RECKONING, 0)     # paper: stale rule


def test_a_commanded_flow_fraction_is_approached_on_the_auger_ramps_with_the_exact_volume():
    a = ag.AugerParams.from_scenario(scen())
    level, vol = ag.flow_advance(1.0, True, 0.3, a, 0.25)          # down at 1/run_out (1 s): reached after 0.75
    assert level == pytest.approx(0.7)
    assert vol == pytest.approx(a.flow_m3ps * (1.0 * 0.3 - 0.5 * 0.3 ** 2))
    level, vol = ag.flow_advance(0.7, True, 1.0, a, 0.25)
    assert level == 0.25 and vol == pytest.approx(a.flow_m3ps * (0.7 * 0.45 - 0.5 * 0.45 ** 2 + 0.25 * 0.55))
    assert ag.flow_advance(0.4, True, 0.1, a, 1.0) == ag.flow_advance(0.4, True, 0.1, a)     # full flow: as before


def _high_flow(*sets):
    s = load_scenario(packaged_scenarios()["high_flow"], ["field.draw=[]", *sets], extra={"feedback": "ground_truth",
                                                                            "renderer": "none"})
    return s, simulate(s)


def test_the_lead_fixes_high_flow_overfill_and_switched_off_it_comes_back():
    """(The overfull guard, which keeps grain off a section already above the target, is switched off too.)"""
    s, r = _high_flow()
    out = _outcome(s, r)
    assert out["status"] == "filled", out["reason"]
    assert r.heights.max() - s.controller.target_fill_m <= s.outcome.overfill_tolerance_m
    assert np.any(r.series["dyn_state.flow_level"] == s.controller.coping.slow_flow)      # it slowed the auger
    s0, r0 = _high_flow("controller.coping.full_lead_s=0", "controller.coping.overfull_margin_m=100")
    assert r0.heights.max() - s0.controller.target_fill_m > 0.10          # the coping is what removes the 15 cm
    assert _outcome(s0, r0)["reason"].startswith("overfill 15 cm in section")


def test_require_filled_passes_a_filled_run(tmp_path, shm_clean):
    assert main(["run", "high_flow", "--renderer", "none", "--feedback", "ground_truth", "--quiet", "--out",
                 str(tmp_path / "r"), "--require-filled"]) == 0


def _lost_after(t0_s: float, period_s: float):
    return lambda truth, frame: truth if frame * period_s < t0_s else None


def test_perception_lost_dead_reckoning_fills_on_while_confident_then_holds_and_says_why():
    blind = scen(controller={"coping": {"fallback_sigma_m": 0.02}})
    r = simulate(blind, measure=_lost_after(30.0, 0.1))
    mode_ = r.series["dyn_state.control_mode"]
    t = r.series["dyn_state.t_s"]
    reckoning = t[mode_ == MODE_DEAD_RECKONING]
    assert reckoning.min() >= 30.0 and reckoning.size > 20        # it went on filling blind for a while ...
    held = np.flatnonzero(r.series["dyn_state.hold_reason"] == HOLD_LOST)
    assert held.size and np.all(np.diff(held) == 1) and held[-1] == len(t) - 1      # ... then held to the end
    assert r.series["dyn_state.estimate_sigma_m"][held[0]] > 0.02
    assert np.all(r.series["dyn_state.auger_on"][held] == 0) and r.series["dyn_state.flow_level"][-1] == 0.0
    out = _outcome(blind, r)
    assert out["status"] == "stopped_safe" and "1-sigma reached 2." in out["reason"]
    # with the default confidence limit the same loss is ridden out: the cart is filled on dead reckoning
    s = scen()
    assert _outcome(s, simulate(s, measure=_lost_after(30.0, 0.1)))["status"] == "filled"


@pytest.mark.parametrize("radius_m", [60.0, -80.0])
def test_the_steady_turn_closed_form_matches_the_vehicle_model_at_steady_state(radius_m):
    s = scen(combine={"path": "arc", "path_radius_m": abs(radius_m)})
    p = VehicleParams.from_scenario(s)
    p = dataclasses.replace(p, combine_yaw_rate_radps=math.copysign(p.combine_yaw_rate_radps, radius_m))
    g, sp = SyncGains.from_scenario(s), (s.machine_sync.longitudinal_offset_m, s.machine_sync.lateral_offset_m)
    xs = initial_state(s, p).tolist()
    for _ in range(9000):                                   # 90 s: the lags and the trailer have settled
        xs = step_exponential_values(xs, sync_command(xs, sp, p, g), p, 0.01)
    x = np.array(xs)
    long_m, lat_m, yaw = steady_cart_offset(p.combine_yaw_rate_radps, sp, p)
    assert cart_offset(x, p) == pytest.approx((long_m, lat_m), abs=1e-5)
    assert cart_pose(x, p)[2] - x[CYAW] == pytest.approx(yaw, abs=1e-6)
    assert abs(lat_m - sp[1]) > 0.3                           # the off-tracking it compensates is real


def test_turn_compensation_keeps_the_spout_on_its_line_and_is_zero_on_a_straight():
    s = scen(combine={"path": "arc", "path_radius_m": 60.0})
    p = ModelParams.from_scenario(s)
    sp, spout = (s.machine_sync.longitudinal_offset_m, s.machine_sync.lateral_offset_m), np.add(p.auger.pivot,
                                                                                             p.auger.arm)
    w = p.vehicles.combine_yaw_rate_radps
    dlat, dx = turn_compensation(w, sp, p.vehicles, spout, p.grid_from_cart_body)
    turned = _spout_grid(spout, steady_cart_offset(w, (sp[0], sp[1] + dlat), p.vehicles), p.grid_from_cart_body)
    straight = _spout_grid(spout, (sp[0], sp[1], 0.0), p.grid_from_cart_body)
    assert turned[1] == pytest.approx(straight[1], abs=1e-6) and turned[0] - straight[0] == pytest.approx(dx)
    assert turn_compensation(0.0, sp, p.vehicles, spout, p.grid_from_cart_body) == (0.0, 0.0)


def test_feedforward_keeps_the_spout_over_the_cart_centreline_in_a_tight_turn():
    rms = {}
    for ff in (True, False):
        s = scen(combine={"path": "arc", "path_radius_m": 60.0}, controller={"coping": {"feedforward": ff}})
        r = simulate(s)
        off = r.series["dyn_state.actual_auger_y_m"] - s.cart.interior_width_m / 2.0
        rms[ff] = float(np.sqrt(np.mean(off ** 2)))
        assert _outcome(s, r)["status"] == "filled"
    assert rms[True] < 0.06 and rms[False] > 0.2, rms


def _dusty(bogus_every: int, t0_s: float = 40.0, t1_s: float = 70.0, period_s: float = 0.1):
    """Truth outside [t0, t1) s; inside, nothing seen but every ``bogus_every``-th frame a map of a "cart" found
    in a dust cloud: 1.8 m over every cell (what the controller would read as nine full sections)."""
    def measure(truth, frame):
        t = frame * period_s
        if not t0_s <= t < t1_s:
            return truth
        return np.full_like(truth, 1.8) if frame % bogus_every == 0 else None
    return measure


def test_a_map_that_disagrees_with_the_estimate_everywhere_is_rejected_whole():
    """A cart 'found' in dust (a bogus map every 2 s of a 30 s gust) would latch sections full that got no grain
    (the run ends declared full with sections short of the target); the estimator's gate rejects such maps and
    the controller fills on by dead reckoning. Without the gate (gate_sigma 1e6) the same run fails."""
    s = scen()
    r = simulate(s, measure=_dusty(20))
    assert _outcome(s, r)["status"] == "filled"
    assert np.all(r.series["dyn_state.control_mode"][(r.series["dyn_state.t_s"] >= 41.0)
                                                     & (r.series["dyn_state.t_s"] < 70.0)] != MODE_MEASURED)
    open_gate = scen(controller={"fusion": {"gate_sigma": 1e6}})
    out = _outcome(open_gate, simulate(open_gate, measure=_dusty(20)))
    assert out["status"] != "filled", out


def test_a_rise_measured_at_the_slowed_flow_is_judged_at_the_nominal_flow_while_a_release_is_pending():
    from dynamics_proc.control.flowlead import commanded_level, level_filter, rise_at_nominal
    dt, tau, k = 0.1, 2.0, 0.2                     # a section that rises k m/s per unit of flow level
    rate, level_f, h = np.zeros(1), 0.0, np.zeros(1)
    for n in range(80):                            # the flow level steps 1 -> 0.3: rise and level, one filter
        level = 1.0 if n < 30 else 0.3
        rate = rise_rate(rate, h, h + k * level * dt, dt, tau)
        h = h + k * level * dt
        level_f = level_filter(level_f, level, dt, tau)
        assert rate[0] == pytest.approx(k * level_f, rel=1e-12)      # the same lag: their ratio is k throughout
    assert rise_at_nominal(rate, level_f, 0, 1, 0.3)[0] == pytest.approx(k, rel=1e-9)  # pending: at nominal
    assert rise_at_nominal(rate, level_f, -1, 1, 0.3) is rate                 # nothing slowed: as measured
    assert rise_at_nominal(rate, level_f, 1, 1, 0.3) is rate                  # slowed for the target itself
    assert rise_at_nominal(rate, 0.0, 0, 1, 0.3)[0] == pytest.approx(rate[0] / 0.3)   # auger off: floored
    assert (commanded_level(False, 0, 0.3), commanded_level(True, 2, 0.3), commanded_level(True, -1, 0.3)) == (
        0.0, 0.3, 1.0)
    # the mechanism: section 0 slowed and full, the impact travelling into target 1 at 1.85 m, which rises 5 cm/s
    # at the slowed flow. As measured (5 cm over the lead, within the 6 cm allowance) the full flow would come
    # back on it on arrival; judged at the nominal flow (17 cm) the slowing carries on to it
    full, heights = np.array([True, False, False]), np.array([1.9, 1.85, 1.0])
    args = dict(lead_s=1.0, allowance_m=0.06, full_level_m=1.89, centres_m=(1.0, 3.0, 5.0), section_m=2.0)
    measured = np.array([0.0, 0.05, 0.0])
    assert slowed_section(1, 0, full, heights, measured, 2.5, SlowLimits(**args)) == -1
    assert slowed_section(1, 0, full, heights, rise_at_nominal(measured, 0.3, 0, 1, 0.3), 2.5, SlowLimits(**args)) == 1


def test_the_default_scenario_never_has_a_release_pending(monkeypatch):
    """The lead acts on the default scenario's last section only, so the nominal-flow judgement, switched on, never
    applies there (docs/field.md); at five times the flow (high_flow, where it is on) it applies."""
    import dynamics_proc.control.controller as ctl
    from dynamics_proc.control.flowlead import rise_at_nominal
    pending = []

    def spy(rate, level_f, slowed, target, slow_flow):
        out = rise_at_nominal(rate, level_f, slowed, target, slow_flow)
        pending.append(out is not rate)
        return out

    monkeypatch.setattr(ctl, "rise_at_nominal", spy)
    s = load_scenario(packaged_scenarios()["default"], extra={"feedback": "ground_truth", "renderer": "none",
                                                               "controller": {"coping": {"lead_at_nominal_flow": True}}})
    r = simulate(s)
    assert len(pending) == len(r.series["dyn_state.t_s"]) - 1 and not any(pending)
    pending.clear()
    simulate(_high_flow()[0])
    assert sum(pending) > 10
