"""Dashboard panels on hand-made snapshots: discovery, absence, drawings; the page; replay of a recording."""
from __future__ import annotations

import json
import threading
import urllib.request

import cv2
import numpy as np
import pytest
import test_viewer_standins as standins

from cosim.recording import mcap_sink
from cosim.runtime.launcher import launch
from cosim.viewer.draw import UNKNOWN
from cosim.viewer.page import page_html
from cosim.viewer.panels import (
    IMAGE_PANELS,
    MAP_MARGIN_BOTTOM,
    MAP_MARGIN_LEFT,
    MAP_MARGIN_TOP,
    MAP_W,
    PANELS,
    panel_info,
    render_panel,
)
from cosim.viewer.replay import ReplaySource
from cosim.viewer.server import DashboardServer
from cosim.viewer.snapshot import Snapshot, auger_now, fullness
from cosim.viewer.viewinfo import ViewInfo


def decode(png: bytes) -> np.ndarray:
    img = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)
    assert img is not None
    return img


def full_snapshot(frame: int = 10) -> Snapshot:
    dyn = {"t_s": 1.0, "desired_auger_x_m": 2.0, "actual_auger_x_m": 1.5, "section2_fullness": 0.5,
           "section1_fullness": 1.0, "section3_fullness": float("nan")}
    rgb = np.zeros((48, 64, 4), np.uint8)
    rgb[..., 0] = 255  # red
    return Snapshot(frame=frame, structs={"dyn_state": dyn},
                    images={"cam0_rgb": rgb, "cam1_rgb": rgb, "cam0_depth": rgb.copy()},
                    arrays={"lidar_points": standins.points(frame), "heightmap_truth": standins.truth(frame),
                            "heightmap_perceived": np.full((30, 15), np.nan, np.float32),
                            "cam_tof_measured": _tof_depth()},
                    frames={"dyn_state": frame, "cam0_rgb": frame, "cam1_rgb": frame - 1, "cam0_depth": frame,
                            "lidar_points": frame, "heightmap_truth": frame, "heightmap_perceived": frame,
                            "cam_tof_measured": frame})


def _tof_depth() -> np.ndarray:
    """A camera sensor's measured depth (docs/cameras.md): 2 m on the left, 4 m on the right, a NaN column."""
    z = np.full((24, 32), 2.0, np.float32)
    z[:, 16:] = 4.0
    z[:, 10] = np.nan
    return z


def test_discovery_of_fields():
    snap = full_snapshot()
    assert fullness(snap.structs)[0] == "dyn_state"
    np.testing.assert_array_equal(fullness(snap.structs)[1], [1.0, 0.5, np.nan])
    assert auger_now(snap.structs) == ("dyn_state", 2.0, 1.5)
    assert snap.t_s == 1.0
    assert fullness({"x": {"a": 1.0}}) is None and auger_now({}) is None and Snapshot().t_s is None


def test_every_panel_present_with_its_frame():
    info = panel_info(full_snapshot(10))
    assert set(info) == set(PANELS)
    assert all(v["available"] for v in info.values())
    assert info["rgb"]["frame"] == 10 and info["fullness"]["frame"] == 10


def test_a_run_without_rgb_shows_the_panel_absent_not_an_error():
    snap = full_snapshot()
    for name in ("cam0_rgb", "cam1_rgb"):
        del snap.images[name], snap.frames[name]
    del snap.structs["dyn_state"]["desired_auger_x_m"], snap.structs["dyn_state"]["actual_auger_x_m"]
    info = panel_info(snap)
    assert info["rgb"] == {"available": False, "frame": None,
                           "note": "absent: this run renders no RGB image (start it with --viewer)"}
    assert not info["auger"]["available"] and info["depth"]["available"]
    assert render_panel(snap, "rgb") is None
    with pytest.raises(KeyError, match="no image panel 'auger'"):
        render_panel(snap, "auger")


def test_camera_sensor_depth_near_red_far_blue_invalid_grey():
    info = panel_info(full_snapshot())["cameras"]
    assert info == {"available": True, "frame": 10, "note": "cam_tof_measured"}
    img = decode(render_panel(full_snapshot(), "cameras"))
    assert img.shape == (24 + 4, 32, 3)
    near, far, invalid = img[5, 2], img[5, 30], img[5, 10]
    assert near[2] > near[0] and far[0] > far[2], (near, far)          # BGR: red near, blue far
    assert tuple(invalid) == UNKNOWN[::-1]


def test_camera_images_side_by_side_in_rgb_order():
    img = decode(render_panel(full_snapshot(), "rgb"))
    assert img.shape == (48, 128, 3)
    assert tuple(img[5, 5]) == (0, 0, 255), "RGBA red must come out red (BGR 0, 0, 255)"


def test_heightmaps_share_a_scale_with_metre_axes_and_grey_unknown():
    snap = full_snapshot()
    img = decode(render_panel(snap, "heightmaps", (6.0, 3.0)))
    w, top, left = MAP_W, MAP_MARGIN_TOP, MAP_MARGIN_LEFT
    h = round(w * 3.0 / 6.0)
    assert img.shape[0] == h + MAP_MARGIN_TOP + MAP_MARGIN_BOTTOM and w >= 500, "large enough to read"
    right = img[top + 2:top + h - 2, 2 * left + w + 2:2 * (left + w) - 2]
    assert (right == UNKNOWN).all(axis=2).mean() > 0.99, "unknown cells of the perceived map are grey"
    # the truth map's peak cell is drawn in the top colour of the shared scale (viridis at 255), seen from
    # above: x (front wall) to the right, y (left wall) up
    truth = standins.truth(10)
    i, j = np.unravel_index(np.nanargmax(truth), truth.shape)
    px = img[top + int((truth.shape[1] - j - 0.5) * h / truth.shape[1]), left + int((i + 0.5) * w / truth.shape[0])]
    top_colour = cv2.applyColorMap(np.array([[255]], np.uint8), cv2.COLORMAP_VIRIDIS)[0, 0]
    np.testing.assert_array_equal(px, top_colour)


def test_page_is_self_contained():
    html = page_html()
    assert "<script>" in html and "http" not in html.replace("http://", "").lower().split("<script>")[0]
    assert "src=\"http" not in html and "href=\"http" not in html
    for pid in PANELS:
        assert f'id="p-{pid}"' in html


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    out = tmp_path_factory.mktemp("replay") / "run"
    res = launch(standins.scenario(1.0), out, specs=standins.specs(), console_log=False, sinks=[mcap_sink()])
    assert res.completed
    return out / "recording.mcap"


def test_replay_gives_back_the_recorded_blocks(recording):
    src = ReplaySource(recording, speed=1e6)
    snap = src.snapshot()
    last = standins.scenario(1.0).frames
    assert snap.frame == last and snap.status == "replay ended"
    assert snap.images["cam0_rgb"].shape == (standins.IMG_H, standins.IMG_W, 3)
    want = standins.points(last)
    np.testing.assert_allclose(snap.arrays["lidar_points"], want[np.isfinite(want[:, 0])])
    np.testing.assert_array_equal(snap.arrays["heightmap_truth"], standins.truth(last))
    assert src.view == ViewInfo.of(standins.scenario(1.0)), "the recording's view record"
    info = panel_info(snap)
    assert all(v["available"] for k, v in info.items() if k != "cameras")
    assert not info["cameras"]["available"], "a LiDAR run has no camera sensor (tests/test_camera_observers.py)"
    assert len(src.history.as_json()["t"]) == last + 1
    with pytest.raises(ValueError, match="replay speed must be > 0"):
        ReplaySource(recording, speed=0)


def test_replay_served_to_the_dashboard(recording):
    srv = DashboardServer(ReplaySource(recording, speed=1e6), port=0)
    t = threading.Thread(target=srv.serve_forever, kwargs={"poll_interval": 0.1}, daemon=True)
    t.start()
    try:
        state = json.loads(urllib.request.urlopen(srv.url + "api/state", timeout=10).read())
        assert state["status"] == "replay ended" and state["panels"]["lidar_side"]["available"]
        for pid in (p for p in IMAGE_PANELS if p != "cameras"):            # no camera sensor in this run
            with urllib.request.urlopen(f"{srv.url}panel/{pid}.png", timeout=10) as r:
                assert r.headers["Content-Type"] == "image/png" and decode(r.read()).size > 0
        page = urllib.request.urlopen(srv.url, timeout=10).read().decode()
        assert "graincosim viewer" in page
    finally:
        srv.shutdown()
        srv.server_close()
