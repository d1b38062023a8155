"""A camera-only run in process with the mock renderer: every camera block written each frame, the depth
camera's record against the exact ray cast, the plug-in input's sensors (docs/cameras.md)."""
from __future__ import annotations

import csv
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cosim.runtime.inprocess import simulate
from cosim.scenario.loader import load_scenario_text

TOF = """format_version: 1
name: tof_probe
renderer: mock
duration_s: 0.3
perception:
  accuracy_every_frames: 1
sensors:
  tof:
    kind: depth_camera
    profile: tof_kinect_class
    range_max_m: 8.0
    labels: true
    mount: {parent: combine, xyz_m: [-3.5, 5.0, 6.0], rpy_deg: [0.0, 52.0, 116.0]}
"""


@pytest.mark.parametrize("noise", [False, True])
def test_a_depth_camera_alone_finds_the_cart_and_reports_its_error(noise):
    s = load_scenario_text(TOF, overrides=[f"sensors.tof.noise={str(noise).lower()}"], check_world=True)
    run = simulate(s)
    ser = run.recorder.series()
    assert np.all(ser["perc_state.cart_valid"] == 1)
    assert np.all(ser["sensor_tof.acc_evaluated"] == 1) and np.all(ser["sensor_tof.frame"] == ser["frame"])
    err, p99 = ser["sensor_tof.depth_err_mean_m"], ser["sensor_tof.depth_err_p99_m"]
    if not noise:
        # exact rendered depth against the exact cast of the same pixels (numpy and Embree casters); what is
        # missing is beyond 80 deg of incidence (the walls and the ground seen edge-on)
        assert np.all(p99 < 1e-4) and np.all(ser["sensor_tof.coverage"] > 0.85)
        assert np.all(ser["sensor_tof.fill_rel_err"] < 0.02)
    else:
        # Nguyen et al.: sigma_z 1.4-8.4 cm over 3.6-7 m; the median |error| is about 0.67 sigma
        assert np.all((0.01 < ser["sensor_tof.depth_err_median_m"]) & (ser["sensor_tof.depth_err_median_m"] < 0.06))
        assert np.all(p99 > 0.1), "flying pixels and lateral noise at edges give a heavy tail"
        assert np.all(err > ser["sensor_tof.depth_err_median_m"])
    arrays = run.recorder.arrays
    assert "cam_tof_depth" not in arrays or arrays["cam_tof_depth"].dtype == np.float32


EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "own_camera_perception"


def test_a_plugin_reads_camera_images_in_simulation_and_launched(tmp_path, shm_clean):
    """examples/own_camera_perception: the algorithm maps the grain from inp.sensors["rgbd"].rgb (grain by
    colour) and .depth_m: within a few cm of the truth in cosim.Simulation; without the colour image
    (``rgb: false``) it has nothing to map; and the same in a launched run."""
    from cosim import Simulation
    from perception_proc.accuracy.stage import heightmap_error, truth_on_grid

    with Simulation(EXAMPLE / "scenario.yaml", duration=0.5) as sim:
        state = sim.step(4)
        perceived, truth = state["heightmap_perceived"], state["heightmap_truth"]
        s = sim.scenario
        rmse, bias, coverage = heightmap_error(perceived, truth_on_grid(truth, s.grain.cell_m, perceived.shape,
                                                                        s.cart))
        assert coverage > 0.5 and rmse < 0.05 and abs(bias) < 0.02, (rmse, bias, coverage)
    with Simulation(EXAMPLE / "scenario.yaml", duration=0.5, set=["sensors.rgbd.rgb=false"]) as sim:
        state = sim.step(4)
        assert state["perc_state.cart_valid"] == 1 and np.all(np.isnan(state["heightmap_perceived"]))
    out = tmp_path / "run"
    done = subprocess.run([sys.executable, "launch.py", "run", str(EXAMPLE / "scenario.yaml"), "--duration", "0.5",
                           "--quiet", "--out", str(out)], cwd=EXAMPLE.parent.parent, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr
    rows = list(csv.DictReader((out / "timeseries.csv").open()))
    assert float(rows[-1]["perc_state.coverage"]) > 0.5
