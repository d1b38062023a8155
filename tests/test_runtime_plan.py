"""Who takes part in a run, and the two transports giving the same results."""
from __future__ import annotations

import numpy as np
import pytest

from cosim.runtime.inprocess import simulate
from cosim.runtime.launcher import launch
from cosim.runtime.lockstep import RingPlan
from cosim.runtime.specs import DEFAULT_SPECS, SUPERVISOR, ring_specs
from cosim.scenario.config import Scenario
from cosim.testing import fakes


@pytest.mark.parametrize("feedback, renderer, viewer, ring", [
    ("ground_truth", "gl", False, ("dynamics",)),
    ("ground_truth", "none", False, ("dynamics",)),
    ("ground_truth", "mock", True, ("dynamics", "renderer", "perception")),
    ("perception", "gl", False, ("dynamics", "renderer", "perception")),
    ("perception", "mock", False, ("dynamics", "renderer", "perception")),
])
def test_participants_the_scene_needs(feedback, renderer, viewer, ring):
    sc = Scenario(format_version=1, feedback=feedback, renderer=renderer, viewer=viewer)
    assert sc.participants == ring
    assert [s.name for s in ring_specs(sc)] == list(ring)
    assert all(s is DEFAULT_SPECS[s.name] for s in ring_specs(sc))


def test_ring_plan_closes_through_the_supervisor():
    plan = RingPlan(("dynamics", "renderer", "perception"), 10)
    assert [plan.next_of(n) for n in ("dynamics", "renderer", "perception", SUPERVISOR)] == \
        ["renderer", "perception", SUPERVISOR, "dynamics"]
    solo = RingPlan(("dynamics",), 10)
    assert solo.next_of("dynamics") == SUPERVISOR and solo.next_of(SUPERVISOR) == "dynamics"


def test_inprocess_and_os_process_transports_agree(tmp_path, shm_clean):
    sc = Scenario(format_version=1, duration_s=1.0, renderer="mock")
    a = simulate(sc, fakes.specs()).recorder.series()
    res = launch(sc, tmp_path / "run", specs=fakes.specs(), console_log=False)
    assert res.completed
    import csv

    with open(tmp_path / "run" / "timeseries.csv") as f:
        rows = list(csv.DictReader(f))
    for col, values in a.items():
        assert np.array_equal(values, np.array([float(r[col]) for r in rows])), col
    assert np.array_equal(res.arrays["heightmap_truth"], np.full((6, 3), sc.frames * 0.01, np.float32))


def test_frames_follow_duration_and_period():
    sc = Scenario(format_version=1, duration_s=12.0)
    assert sc.frames == 120 and sc.timing.steps_per_frame == 10
    sc = Scenario.model_validate({"format_version": 1, "duration_s": 1.05,
                                  "timing": {"sensor_period_s": 0.1, "dynamics_dt_s": 0.025}})
    assert sc.frames == 11 and sc.timing.steps_per_frame == 4
