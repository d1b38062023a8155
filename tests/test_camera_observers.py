"""Every camera sensor in the observers (docs/cameras.md, docs/foxglove.md): the recording's camera topics and
frames, the replay's blocks, the dashboard's camera panel."""
from __future__ import annotations

import numpy as np
import pytest

from cosim import Simulation
from cosim.recording.encode import image_from_msg, points_from_cloud
from cosim.recording.reader import read_recording
from cosim.viewer.panels import panel_info, render_panel
from cosim.viewer.replay import ReplaySource
from cosim.world.sensors import camera_pinhole
from perception_proc.cameras.depth_models import normal_sigma_m
from perception_proc.cameras.jump_edges import flying_pixels, jump_threshold

SCENARIO = """format_version: 1
name: cams_recorded
renderer: mock
duration_s: 1.0
sensors:
  tof:
    kind: depth_camera
    profile: tof_kinect_class
    rgb: true
    labels: true
    range_max_m: 8.0
    points_stride: 1
    mount: {parent: combine, xyz_m: [-3.5, 5.0, 6.0], rpy_deg: [0.0, 52.0, 116.0]}
"""


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    out = tmp_path_factory.mktemp("cams")
    path = out / "scenario.yaml"
    path.write_text(SCENARIO)
    with Simulation(path, out=out / "run", record=True) as sim:
        sim.step(10)
        last = {k: np.array(sim.state[k]) for k in ("cam_tof_measured", "cam_tof_points", "cam_tof_labels")}
        scenario = sim.scenario
    return read_recording(out / "run" / "recording.mcap"), out / "run" / "recording.mcap", last, scenario


def test_each_camera_has_its_topics_calibration_and_frames(recorded):
    rec, _, _, scenario = recorded
    for topic, schema in (("/cam_tof/rgb", "foxglove.CompressedImage"), ("/cam_tof/depth", "foxglove.RawImage"),
                          ("/cam_tof/depth_exact", "foxglove.RawImage"), ("/cam_tof/labels", "foxglove.RawImage"),
                          ("/cam_tof/points", "foxglove.PointCloud"),
                          ("/cam_tof/calibration", "foxglove.CameraCalibration")):
        assert rec.channels[topic].schema == schema and rec.messages[topic], topic

    pin = camera_pinhole(scenario.cameras["tof"], scenario)
    cal = rec.messages["/cam_tof/calibration"][-1][1]
    assert (cal["width"], cal["height"], cal["frame_id"]) == (pin.width, pin.height, "cam_tof_optical")
    # Foxglove puts pixel centres at integers: the principal point is ours less half a pixel
    np.testing.assert_allclose(cal["K"], [pin.f, 0, pin.width / 2 - 0.5, 0, pin.f, pin.height / 2 - 0.5, 0, 0, 1])
    children = {(t["parent_frame_id"], t["child_frame_id"]) for _, m in rec.messages["/tf"]
                for t in m.get("transforms", [m])}
    assert {("combine", "cam_tof"), ("cam_tof", "cam_tof_optical")} <= children


def test_depth_labels_and_points_come_back_whole(recorded):
    """The recorded depth is float32 planar depth of the camera's size; the labels are label codes; the points
    of a frame are that frame's valid pixels but its flying ones (``points_stride: 1``; a depth camera keeps its
    own size under the mock)."""
    rec, _, last, scenario = recorded
    t, msg = rec.messages["/cam_tof/depth"][-1]
    depth = image_from_msg(msg)
    assert depth.dtype == np.float32 and depth.shape == last["cam_tof_measured"].shape
    labels = image_from_msg(rec.messages["/cam_tof/labels"][-1][1])
    assert labels.dtype == np.uint8 and set(np.unique(labels)) <= set(range(9))
    pts = dict(rec.messages["/cam_tof/points"])[t]
    spec = scenario.cameras["tof"]
    z = np.nan_to_num(depth.astype(np.float64), nan=1.0)
    jump = jump_threshold(z, normal_sigma_m(spec, z), camera_pinhole(spec, scenario).f, spec.max_incidence_deg)
    flying = flying_pixels(depth, jump)
    assert 0 < flying.sum() < 0.1 * np.isfinite(depth).sum()
    assert len(points_from_cloud(pts)) == (np.isfinite(depth) & ~flying).sum() > 1000


def test_the_replay_and_the_dashboard_show_the_camera(recorded):
    _, path, _, _ = recorded
    src = ReplaySource(path)
    src.control("seek", 10)
    snap = src.snapshot()
    assert {"cam_tof_measured", "cam_tof_points", "cam_tof_labels"} <= set(snap.arrays)
    assert "cam_tof_rgb" in snap.images
    info = panel_info(snap, stamps=False)["cameras"]
    assert info["available"] and "cam_tof_measured" in info["note"]
    png = render_panel(snap, "cameras")
    assert png is not None and png[:8] == b"\x89PNG\r\n\x1a\n"
