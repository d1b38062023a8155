"""Same scenario and seed, byte-identical timeseries.csv with every field condition on (terrain, Machine Sync
errors, flow variation, dust and the stream's kernels), through the launched process ring."""
from __future__ import annotations

import json

from cosim.runtime.launcher import launch
from cosim.scenario.config import Scenario

FIELD = {"format_version": 1, "renderer": "mock", "duration_s": 2.0, "seed": 5,
         "terrain": {"roughness_rms_m": 0.03, "cross_slope_pct": 2.0},
         "machine_sync": {"gnss": {"sigma": 0.02}, "radio_latency_s": 0.2, "actuation_delay_s": 0.1},
         "tractor": {"slip": {"mean": 0.04, "sigma": 0.02}},
         "auger": {"flow_variation": {"sigma": 0.1}, "start_surge": 0.3},
         "combine": {"profile": [{"t_s": 0, "speed_mps": 2}, {"t_s": 1, "speed_mps": 1.5, "curvature_1pm": 0.01}]},
         "atmosphere": {"visibility_m": 150.0, "stream_particles": True},
         "outputs": {"figures": False}}


def test_field_conditions_repeat_to_the_byte(tmp_path, shm_clean):
    s = Scenario.model_validate_json(json.dumps(FIELD))
    a = launch(s, tmp_path / "a", console_log=False)
    b = launch(s, tmp_path / "b", console_log=False)
    assert a.exit_code == b.exit_code == 0
    ta, tb = (tmp_path / "a" / "timeseries.csv").read_bytes(), (tmp_path / "b" / "timeseries.csv").read_bytes()
    assert ta == tb and ta.count(b"\n") == s.frames + 2
    assert a.summary["outcome"] == b.summary["outcome"]
