"""The seed's draw of a field case (``field:``; cosim.scenario.config.fielddraw): different seeds are different fields,
every draw within its documented range, the same seed the same field however the scenario is built, a scenario
that draws nothing unchanged, bad ranges refused at their keys."""
from __future__ import annotations

import textwrap

import numpy as np
import pytest

from cosim.errors import ScenarioError
from cosim.scenario.config.fielddraw import OWNED
from cosim.scenario.loader import dump_resolved, load_scenario, load_scenario_text, packaged_scenarios
from dynamics_proc.closed_loop import simulate

CASES = ("rough_terrain", "side_slope", "gnss_noise", "stop_and_go", "headland_turn", "dusty", "dense_dust",
         "high_flow", "grazing_sensor")


def _case(name: str, seed: int, *sets: str, **extra):
    return load_scenario(packaged_scenarios()[name], list(sets), extra={"seed": seed, **extra})


def _flow(name: str, seed: int, seconds: float) -> np.ndarray:
    s = _case(name, seed, f"duration_s={seconds}", feedback="ground_truth", renderer="none")
    return np.asarray(simulate(s).series["dyn_state.flow_factor"])


def test_two_seeds_of_high_flow_see_different_grain_flows_and_one_seed_the_same():
    a, b, again = _flow("high_flow", 1000, 20.0), _flow("high_flow", 1001, 20.0), _flow("high_flow", 1000, 20.0)
    assert np.array_equal(a, again)
    assert np.ptp(a) > 0.02 and np.ptp(b) > 0.02                       # the flow varies within a run
    assert np.max(np.abs(a - b)) > 0.03                                # and differently from seed to seed


def test_every_case_states_what_it_draws_and_every_draw_stays_in_its_range():
    for name in CASES:
        assert _case(name, 0, renderer="mock").field.draw, name
    lows = {}
    for seed in range(40):
        s = _case("dense_dust", seed, renderer="mock")
        f = s.field
        lo, hi = f.flow.sigma
        assert lo <= s.auger.flow_variation.sigma <= hi
        assert f.flow.correlation_time_s[0] <= s.auger.flow_variation.correlation_time_s <= f.flow.correlation_time_s[1]
        assert f.dust.visibility_m[0] <= s.atmosphere.visibility_m <= f.dust.visibility_m[1]
        start, end = s.atmosphere.dust_window_s
        assert f.dust.start_s[0] <= start <= f.dust.start_s[1]
        assert f.dust.length_s[0] <= end - start <= f.dust.length_s[1]
        assert abs(s.combine.speed_mps / 2.0 - 1.0) <= f.profile.speed
        assert f.offsets.long_m[0] <= s.machine_sync.initial_long_error_m <= f.offsets.long_m[1]
        assert f.offsets.lat_m[0] <= s.machine_sync.initial_lat_error_m <= f.offsets.lat_m[1]
        lows.setdefault("visibility", []).append(s.atmosphere.visibility_m)
    vis = lows["visibility"]                                           # the draws spread over their range
    assert min(vis) < 17.0 and max(vis) > 23.0 and len(set(vis)) == len(vis)


def test_profile_jitter_keeps_the_events_in_order_and_within_their_bounds():
    base = load_scenario(packaged_scenarios()["stop_and_go"], ["field.draw=[]"], extra={"renderer": "mock"})
    times0 = [p.t_s for p in base.combine.profile]
    for seed in range(30):
        s = _case("stop_and_go", seed, renderer="mock")
        times = [p.t_s for p in s.combine.profile]
        assert times[0] == times0[0] and all(b > a for a, b in zip(times, times[1:]))
        spec = s.field.profile
        for t, t0 in zip(times[1:], times0[1:]):
            assert spec.shift_s[0] - spec.time_s <= t - t0 <= spec.shift_s[1] + spec.time_s
        stops = [p.speed_mps for p in s.combine.profile if p.speed_mps == 0.0]
        assert len(stops) == 2                                         # a stop stays a stop


def test_the_same_seed_draws_the_same_field_however_the_scenario_is_built():
    s = _case("rough_terrain", 7, renderer="mock")
    assert s == _case("rough_terrain", 7, renderer="mock")
    again = load_scenario_text(dump_resolved(s), "<resolved>")          # a child re-validating what it was sent
    assert again == s
    other = load_scenario_text(dump_resolved(s), "<resolved>", extra={"seed": 8})   # drawn from the case again
    assert other == _case("rough_terrain", 8, renderer="mock")
    assert other.terrain.roughness_rms_m != s.terrain.roughness_rms_m
    assert s.field.base["terrain.roughness_rms_m"] == 0.03           # what the draw replaced is recorded


def test_a_scenario_that_draws_nothing_is_unchanged():
    d = load_scenario(packaged_scenarios()["default"])
    assert not d.field.draw and not d.field.base
    undrawn = _case("side_slope", 3, "field.draw=[]", renderer="mock")
    assert undrawn.auger.flow_variation.sigma == 0.0 and undrawn.combine.speed_mps == 2.0
    assert not undrawn.field.base


def test_each_condition_owns_its_keys_only():
    plain = _case("high_flow", 5, "field.draw=[]", renderer="mock").model_dump()
    drawn = _case("high_flow", 5, renderer="mock").model_dump()
    changed = {f"{k}.{j}" for k in plain if k != "field" and plain[k] != drawn[k]
               for j in (plain[k] if isinstance(plain[k], dict) else {"": 0})
               if not isinstance(plain[k], dict) or plain[k][j] != drawn[k][j]}
    owned = {p.rsplit(".", p.count(".") - 1)[0] for c in ("flow", "profile", "offsets") for p in OWNED[c]}
    assert changed and changed <= owned


@pytest.mark.parametrize("block, fragment", [
    ("draw: [flow]\n  flow: {sigma: [0.1, 0.05]}", "field.flow.sigma: a range is [low, high]"),
    ("draw: [gnss]\n  gnss: {sigma_m: [0.01, 0.9]}", "field.gnss.sigma_m: the GNSS sigma is drawn within [0, 0.5] m"),
    ("draw: [wind]", "field.draw[0]: Input should be"),
    ("draw: [flow, flow]", "field.draw: a condition is drawn once: flow repeat"),
    ("draw: [dust]\n  dust: {start_s: [10.0, 20.0]}", "field.dust: start_s and length_s are drawn together"),
])
def test_bad_draws_are_refused_at_their_keys(block, fragment):
    text = "format_version: 1\nrenderer: none\nfeedback: ground_truth\nfield:\n  " + block + "\n"
    with pytest.raises(ScenarioError) as e:
        load_scenario_text(text, "case.yaml")
    assert fragment in str(e.value) and "case.yaml:" in str(e.value)


def test_a_profile_jitter_that_could_reorder_the_events_is_refused():
    text = textwrap.dedent("""\
        format_version: 1
        renderer: none
        feedback: ground_truth
        combine:
          profile: [{t_s: 0.0, speed_mps: 2.0}, {t_s: 10.0, speed_mps: 1.0}, {t_s: 11.0, speed_mps: 2.0}]
        field:
          draw: [profile]
          profile: {time_s: 0.6}
        """)
    with pytest.raises(ScenarioError, match=r"case.yaml:8:\d+: field.profile: .*10 s and 11 s are 1 s apart"):
        load_scenario_text(text, "case.yaml")


@pytest.mark.parametrize("case, override, key", [
    ("high_flow", "auger.flow_variation.sigma=0.05", "auger.flow_variation.sigma"),
    ("high_flow", "machine_sync={initial_lat_error_m: 0.1}", "machine_sync.initial_lat_error_m"),
    ("dusty", "atmosphere.visibility_m=30", "atmosphere.visibility_m"),
    ("rough_terrain", "terrain.roughness_rms_m=0.01", "terrain.roughness_rms_m"),
])
def test_a_value_the_seed_draws_is_refused_when_set_with_its_range_named(case, override, key):
    """A --set of a drawn key would be drawn over unseen: it is refused at the --set, naming the range to set."""
    path = packaged_scenarios()[case]
    with pytest.raises(ScenarioError) as e:
        load_scenario(path, [override])
    text = str(e.value)
    assert text.startswith("<--set>:1:") and f"'{key}' is drawn per seed" in text and "field.draw" in text
    assert "[" in text.split("its ranges:")[1]            # the ranges, to set instead


def test_a_drawn_key_is_free_to_set_once_its_condition_is_off_and_a_jittered_one_always():
    path = packaged_scenarios()["high_flow"]
    s = load_scenario(path, ["field.draw=[profile]", "auger.flow_variation.sigma=0.05", "combine.speed_mps=1.5"])
    assert s.auger.flow_variation.sigma == 0.05
    assert s.field.draw == ("profile",)                   # the speed is jittered around the value set
