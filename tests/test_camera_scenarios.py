"""The packaged camera scenarios (docs/cameras.md): a few frames of each in process (GL), and, marked slow, the
whole fill: stereo_spout and lidar_and_stereo fill from half full to the target with perception feedback, no
spill and at most 5 cm over, lidar_and_stereo's summary with both sensors' blocks."""
from __future__ import annotations

import numpy as np
import pytest

from cosim.runtime.inprocess import simulate
from cosim.runtime.launcher import launch
from cosim.scenario.loader import load_scenario, packaged_scenarios

pytestmark = pytest.mark.gl

#: the acceptance: at most this much above the target, m
MAX_OVERFILL_M = 0.05


@pytest.mark.parametrize("name, sensor", [("stereo_spout", "spout"), ("tof_mast", "tof"),
                                          ("lidar_and_stereo", "spout")])
def test_first_frames_find_the_cart_and_measure_depth(name, sensor):
    s = load_scenario(packaged_scenarios()[name], extra={"duration_s": 0.4, "perception.accuracy_every_frames": 3})
    ser = simulate(s).recorder.series()
    assert np.all(ser["perc_state.cart_valid"][1:] == 1), ser["perc_state.cart_valid"]
    evaluated = ser[f"sensor_{sensor}.acc_evaluated"] == 1
    assert evaluated.any() and np.all(ser[f"sensor_{sensor}.depth_err_median_m"][evaluated] < 0.1)
    assert np.all(ser[f"sensor_{sensor}.fill_rel_err"][evaluated] < 0.08)


@pytest.mark.slow
@pytest.mark.parametrize("name, sensors", [("stereo_spout", {"spout"}), ("lidar_and_stereo", {"mast", "spout"})])
def test_the_camera_fills_the_cart(tmp_path, name, sensors):
    res = launch(load_scenario(packaged_scenarios()[name]), tmp_path / name, console_log=False)
    s = res.summary
    assert res.completed and s["spill"]["mass_kg"] == 0.0
    assert s["fill"]["time_to_target_s"] is not None and s["fill"]["max_overfill_m"] <= MAX_OVERFILL_M
    assert set(s["perception"]["sensors"]) == sensors
    for block in s["perception"]["sensors"].values():
        assert block["frames_evaluated"] > 0 and block["fill_height"]["mean_rel_error"] < 0.06
