"""The dynamics participant over a local segment: blocks, frame 0, latency rule, feedback modes, runtime."""
from __future__ import annotations

import numpy as np
import pytest

from cosim.errors import FrameMismatch
from cosim.scenario.config import Scenario
from dynamics_proc.blocks import declare_blocks
from dynamics_proc.closed_loop import simulate
from dynamics_proc.participant import create
from shm_schema import ArrayBlock, Field, Schema, Segment, StructBlock

FRAMES = 150


def scen(**kw) -> Scenario:
    d = {"format_version": 1, "feedback": "ground_truth", "renderer": "none", "duration_s": 30.0}
    d.update(kw)
    return Scenario.model_validate(d)


def test_blocks_declared_with_units():
    s = scen()
    blocks = {b.name: b for b in declare_blocks(s)}
    assert set(blocks) == {"dyn_state", "stream", "heightmap_truth"}
    assert blocks["stream"].shape == (64, 4) and blocks["stream"].dtype == "<f4"
    assert blocks["heightmap_truth"].shape == (60, 30) and blocks["heightmap_truth"].dtype == "<f4"
    names = [f.name for f in blocks["dyn_state"].fields]
    for need in ("t_s", "combine_x_m", "tractor_yaw_rad", "cart_x_m", "spout_z_m", "auger_on", "flow_m3ps",
                 "impact_x_m", "impact_valid", "stream_points", "desired_auger_x_m", "control_effort_m", "nudge_m",
                 "actual_auger_x_m", "delivered_m3", "in_cart_m3", "spilled_m3", "section9_fullness"):
        assert need in names
    units = {f.name: f.unit for f in blocks["dyn_state"].fields}
    assert units["t_s"] == "s" and units["flow_m3ps"] == "m^3/s" and units["cart_yaw_rad"] == "rad"


def _local(s: Scenario, extra=()):
    return Segment.local(Schema(list(declare_blocks(s)) + list(extra), ["dynamics", "perception", "supervisor"]))


def test_frame0_publishes_initial_state_and_order_is_checked():
    s = scen()
    seg = _local(s)
    p = create(s)
    p.start(seg)
    with pytest.raises(FrameMismatch, match="expected frame 0, got 1"):
        p.step(1)
    p.step(0)
    v = seg.view("dyn_state")
    assert v.t_s == 0.0 and v.frame == 0 and v.auger_on == 0
    assert v.cart_x_m == pytest.approx(-4.65) and v.actual_auger_x_m == pytest.approx(0.35)
    assert seg.frame_of("dyn_state") == seg.frame_of("heightmap_truth") == seg.frame_of("stream") == 0
    assert np.all(seg.view("heightmap_truth") == np.float32(1.0))
    p.step(1)
    assert seg.view("dyn_state").t_s == pytest.approx(0.1) and seg.frame_of("stream") == 1
    p.close()


def test_ground_truth_participant_equals_pure_closed_loop():
    s = scen()
    seg = _local(s)
    p = create(s)
    p.start(seg)
    for m in range(FRAMES + 1):
        p.step(m)
    ref = simulate(s, FRAMES)
    got = p.series()
    for k, v in ref.series.items():
        np.testing.assert_array_equal(got[k], v, err_msg=k)
    np.testing.assert_array_equal(seg.view("heightmap_truth"), ref.heights.astype(np.float32))
    p.close()


@pytest.mark.parametrize("latency, overlap", [(0, False), (1, False), (3, False), (1, True), (3, True)])
def test_perception_feedback_applies_latency(latency, overlap):
    """A stand-in perception that reports the truth (float32) must give exactly the pure loop whose
    measurement is the same float32 truth, under the same latency rule; overlapping, the stand-in publishes
    P(m) one turn late, after dynamics' frame m + 1 (cosim.runtime.participant), with the same result."""
    s = scen(feedback="perception", renderer="mock",
             timing={"latency_frames": latency, "schedule": "overlapped" if overlap else "sequential"})
    perc = [ArrayBlock("heightmap_perceived", "perception", "f4", (60, 30), unit="m"),
            StructBlock("perc_state", "perception", (Field("t_s", "s"), Field("cart_valid", "", "i8")))]
    seg = _local(s, perc)
    p = create(s)
    p.start(seg)
    from dynamics_proc.model import truth_measurement

    def publish(m, heights):
        with seg.write("heightmap_perceived", m) as hm:
            hm[...] = heights
        with seg.write("perc_state", m) as ps:
            ps.t_s, ps.cart_valid = m * 0.1, 1

    pending = None
    for m in range(FRAMES + 1):
        p.step(m)
        if pending is not None:
            publish(*pending)
            pending = None
        if overlap:
            pending = (m, truth_measurement(p.heights, p.params))
        else:
            publish(m, truth_measurement(p.heights, p.params))
    ref = simulate(s, FRAMES, measure=lambda t, f: t.astype(np.float32).astype(np.float64))
    got = p.series()
    for k in ("dyn_state.auger_on", "dyn_state.delivered_m3", "dyn_state.nudge_m", "dyn_state.section1_fullness",
              "dyn_state.cart_x_m"):
        np.testing.assert_array_equal(got[k], ref.series[k], err_msg=k)
    # the auger cannot start before the first measurement reaches the controller: frame 1 + L acts on P(0)
    first_on = int(np.flatnonzero(got["dyn_state.auger_on"] > 0)[0])
    assert first_on == 1 + latency
    p.close()


def test_missing_or_invalid_perception_is_no_measurement():
    s = scen(feedback="perception", renderer="mock", timing={"latency_frames": 0})
    perc = [ArrayBlock("heightmap_perceived", "perception", "f4", (60, 30), unit="m"),
            StructBlock("perc_state", "perception", (Field("t_s", "s"), Field("cart_valid", "", "i8")))]
    seg = _local(s, perc)
    p = create(s)
    p.start(seg)
    for m in range(30):
        p.step(m)
        if m % 2 == 0:                       # every other frame: valid map but the cart not found
            with seg.write("heightmap_perceived", m) as hm:
                hm[...] = 1.0
            with seg.write("perc_state", m) as ps:
                ps.cart_valid = 0
    assert np.all(p.series()["dyn_state.auger_on"] == 0)
    assert np.all(p.series()["dyn_state.measurement_seen"] == 0)
    p.close()


def test_perception_feedback_needs_a_matching_perceived_block():
    s = scen(feedback="perception", renderer="mock")
    p = create(s)
    with pytest.raises(ValueError, match="no 'heightmap_perceived' block"):
        p.start(_local(s))
    bad = [ArrayBlock("heightmap_perceived", "perception", "f4", (30, 15), unit="m")]
    with pytest.raises(ValueError, match=r"heightmap_perceived is \(30, 15\), the controller grid"):
        create(s).start(_local(s, bad))


def test_runs_in_the_inprocess_runtime_and_summarizes():
    from cosim.runtime.inprocess import simulate as run
    from dynamics_proc.summary import summarize
    s = scen(duration_s=15.0)
    r = run(s)
    series = r.recorder.series()
    ref = simulate(s)
    np.testing.assert_array_equal(series["dyn_state.delivered_m3"], ref.series["dyn_state.delivered_m3"])
    sm = summarize(s, series, r.recorder.arrays.get("heightmap_truth"))
    assert set(sm) == {"fill", "spill", "mass_balance", "controller"}
    assert sm["mass_balance"]["relative_error"] <= 1e-9 and sm["mass_balance"]["delivered_m3"] > 1.0
    assert len(sm["fill"]["section_peak_height_m"]) == 9
