"""Perception overlapping the next frame (cosim.runtime.participant): late publication, the flush turn, same results."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from cosim.runtime.inprocess import simulate
from cosim.runtime.launcher import launch
from cosim.runtime.lockstep import RingPlan
from cosim.runtime.participant import perception_overlaps
from cosim.scenario.config import Scenario
from cosim.testing import fakes

ROLES = ("dynamics", "renderer", "perception")


def scenario(duration_s=1.0) -> Scenario:
    return Scenario(format_version=1, duration_s=duration_s, renderer="mock")


def with_timing(sc: Scenario, **kw) -> Scenario:
    return sc.model_copy(update={"timing": sc.timing.model_copy(update=kw)})


def test_overlap_only_where_the_latency_leaves_a_frame():
    sc = scenario()
    assert perception_overlaps(sc)                                          # perception feedback, L = 1
    assert not perception_overlaps(with_timing(sc, latency_frames=0))
    assert perception_overlaps(with_timing(sc, latency_frames=0).model_copy(update={"feedback": "ground_truth"}))
    assert not perception_overlaps(with_timing(sc, schedule="sequential"))
    assert perception_overlaps(with_timing(sc, schedule="overlapped"))


def test_plan_orders_the_flush_turn():
    plan = RingPlan(ROLES, 5, deferred=("perception",))
    assert plan.flush_frame == 6
    assert plan.flush_next_of("supervisor") == "perception" and plan.flush_next_of("perception") == "supervisor"
    assert RingPlan(ROLES, 5).flush_frame is None
    with pytest.raises(ValueError, match="not in the ring"):
        RingPlan(ROLES, 5, deferred=("viewer",))


def test_rest_from_a_member_that_is_not_deferred_is_refused():
    sc = scenario()
    specs = fakes.specs(perception={"defer": True})
    specs["perception"] = replace(specs["perception"], defers=None)
    with pytest.raises(RuntimeError, match="does not defer"):
        simulate(sc, specs)


def test_deferred_rows_land_on_their_own_frames_inprocess():
    sc = scenario()
    s = simulate(sc, fakes.specs(perception={"defer": True})).recorder.series()
    plain = simulate(sc, fakes.specs()).recorder.series()
    n = sc.frames + 1
    assert len(s["frame"]) == n
    # each row's perception output is that frame's, the last one included (the flush turn)
    assert np.array_equal(s["fake_perc.img_frame"], s["frame"])
    assert np.array_equal(s["fake_perc.checksum"], plain["fake_perc.checksum"])
    # dynamics reads the perception block when the token comes: it holds P(k - 2) instead of P(k - 1)
    assert np.array_equal(s["fake_dyn.perc_frame"][2:], s["frame"][2:] - 2)
    assert np.array_equal(plain["fake_dyn.perc_frame"], plain["frame"] - 1)


def test_os_ring_overlaps_and_matches_inprocess(tmp_path, shm_clean):
    """Over processes the deferred rest (30 ms here) runs while dynamics and the renderer do the next frame, so
    the next frame's dynamics starts before perception's rest has ended, and the records equal in-process."""
    sc = scenario(duration_s=0.5)
    specs = fakes.specs(perception={"defer": True, "rest_s": 0.03})
    res = launch(sc, tmp_path / "run", specs=specs, console_log=False)
    assert res.completed, res.error
    inproc = simulate(sc, specs).recorder.series()
    ts = (tmp_path / "run" / "timeseries.csv").read_text().splitlines()
    header = ts[0].split(",")
    cols = {h: np.array([float(r.split(",")[i]) for r in ts[1:]]) for i, h in enumerate(header)}
    for k in ("fake_perc.img_frame", "fake_perc.checksum", "fake_dyn.perc_frame", "fake_ren.dyn_frame"):
        assert np.array_equal(cols[k], inproc[k]), k
    # trace stamps (monotonic ns at each step's start): dynamics of frame k+1 starts less than the rest's
    # 30 ms after perception of frame k started, i.e. before that rest ended
    dyn = res.arrays["trace_dynamics"][:, 1]
    per = res.arrays["trace_perception"][:, 1]
    gaps_ms = (dyn[1:] - per[:-1]) / 1e6
    assert np.median(gaps_ms) < 25.0, gaps_ms
    assert res.summary["ring"]["overlapped"] is True
    assert "handoff" not in res.summary["timing_ms"]


def test_real_perception_overlapped_gives_the_serial_numbers():
    """The default scene (mock renderer, perception feedback, accuracy evaluated): overlap changes no number but
    the wall-clock ones, and dynamics acts on the same measurements."""
    base = Scenario.model_validate({"format_version": 1, "renderer": "mock", "duration_s": 1.5,
                                    "perception": {"accuracy_every_frames": 5}})
    runs = {}
    for overlap in (True, False):
        sc = with_timing(base, schedule="overlapped" if overlap else "sequential")
        assert perception_overlaps(sc) is overlap
        runs[overlap] = simulate(sc).recorder.series()
    a, b = runs[True], runs[False]
    assert a.keys() == b.keys()
    differ = [k for k in a if not k.endswith("_ms") and not np.array_equal(a[k], b[k], equal_nan=True)]
    assert differ == []
    assert np.array_equal(a["perc_state.frame"], a["frame"])
    assert np.count_nonzero(a["perc_state.acc_evaluated"]) == 4


def test_the_overlap_is_part_of_the_one_schedule_key(tmp_path):
    """``timing.overlap_perception`` is refused at its line with the ``timing.schedule`` values that say it."""
    from cosim.errors import ScenarioError
    from cosim.scenario.loader import load_scenario

    f = tmp_path / "s.yaml"
    f.write_text("format_version: 1\ntiming:\n  overlap_perception: false\n")
    with pytest.raises(ScenarioError, match=r"s\.yaml:3:\d+: timing\.overlap_perception: not a key: .*timing\.schedule: "
                                            r"sequential \(no overlap\), overlapped or pipelined"):
        load_scenario(f)
