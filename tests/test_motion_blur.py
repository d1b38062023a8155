"""Motion blur over the exposure (renderer_proc.motion_blur, docs/cameras.md) against its closed form: a plane at
depth Z moving at v parallel to the image plane for an exposure T smears an edge over f v T / Z px."""
from __future__ import annotations

import math

import numpy as np
import pytest

from cosim.world.camera import Pinhole
from cosim.world.geometry import make_transform
from renderer_proc.motion_blur import MAX_SAMPLES, blur, pixel_displacement

PIN = Pinhole(640, 400, math.radians(72.0))
EDGE_COL = 320


def _edge_plane() -> np.ndarray:
    """(H, W, 4) uint8: a plane's texture with one vertical edge (dark left of EDGE_COL, bright right)."""
    img = np.full((PIN.height, PIN.width, 4), 40, np.uint8)
    img[:, EDGE_COL:, :3] = 220
    img[..., 3] = 255
    return img


def _ramp_width_px(row: np.ndarray) -> float:
    """The 10-90 % rise of an edge's profile ``row`` (W,) divided by 0.8: a box blur's length, px."""
    lo, hi = float(row.min()), float(row.max())
    x = np.arange(row.size, dtype=np.float64)

    def crossing(level: float) -> float:
        y = (row.astype(np.float64) - lo) / (hi - lo)
        k = int(np.argmax(y >= level))
        return x[k - 1] + (level - y[k - 1]) / (y[k] - y[k - 1])

    return (crossing(0.9) - crossing(0.1)) / 0.8


def _centroid(row: np.ndarray) -> float:
    """The mean position (px) of an edge profile's rise."""
    g = np.diff(row.astype(np.float64))
    return float(np.sum(g * np.arange(g.size)) / np.sum(g))


@pytest.mark.parametrize("z_m, v_mps, t_s", [(5.0, 3.3, 0.005), (2.0, 3.3, 0.008), (1.5, 5.0, 0.006),
                                             (5.0, 3.3, 0.02)])
@pytest.mark.parametrize("moving", ["camera", "plane"])
def test_an_edge_on_a_plane_smears_over_f_v_t_over_z(z_m, v_mps, t_s, moving):
    """The camera translating along its X at v, or the plane along the world's X under a still camera: the same
    image motion, f v T / Z px. The edge's rise moves by half of it (the mean over the exposure, to 0.02 px) and,
    where the blur spans 5 px or more (the 10-90 % rise then lies on the box blur's linear ramp, not on the
    pixel's own 1 px interpolation), rises over 0.8 f v T / Z px (3 %)."""
    depth = np.full((PIN.height, PIN.width), z_m, np.float32)
    end = np.eye(4)
    step = make_transform(np.eye(3), (v_mps * t_s, 0.0, 0.0))
    if moving == "camera":      # the camera was v T further back along X when the exposure started
        d = pixel_displacement(depth, PIN, end, np.linalg.inv(step) @ end)
    else:                       # the plane (body 0) was v T further back along X at the start
        d = pixel_displacement(depth, PIN, end, end, np.zeros(depth.shape, int), [np.linalg.inv(step)])
    expected = PIN.f * v_mps * t_s / z_m
    sign = -1.0 if moving == "camera" else 1.0          # the scene slides the other way under a moving camera
    assert np.allclose(d[..., 0], sign * expected, atol=1e-3) and np.allclose(d[..., 1], 0.0, atol=1e-3)  # float32
    img = _edge_plane()
    out = blur(img, d)
    row = PIN.height // 2
    shift = _centroid(out[row, :, 0]) - _centroid(img[row, :, 0])
    assert shift == pytest.approx(-sign * expected / 2.0, abs=0.02), (shift, expected)
    if expected >= 5.0:
        width = _ramp_width_px(out[row, :, 0])
        assert expected < MAX_SAMPLES and width == pytest.approx(expected, rel=0.03), (width, expected)


def test_motion_along_the_optical_axis_is_radial_and_none_leaves_the_bytes():
    """Moving towards a plane the image expands from the principal point (zero there); no motion returns the
    image itself."""
    depth = np.full((PIN.height, PIN.width), 5.0, np.float32)
    start = make_transform(np.eye(3), (0.0, 0.0, -0.05))      # 5 cm further back along the optical axis
    d = pixel_displacement(depth, PIN, np.eye(4), start)
    cy, cx = PIN.height // 2, PIN.width // 2
    assert abs(d[cy, cx]).max() < 0.01
    assert d[cy, -1, 0] > 0 > d[cy, 0, 0] and d[0, cx, 1] < 0 < d[-1, cx, 1]
    img = _edge_plane()
    assert blur(img, np.zeros(depth.shape + (2,), np.float32)) is img
    depth[:10] = np.nan
    assert not pixel_displacement(depth, PIN, np.eye(4), start)[:10].any(), "nothing seen: no motion"


def _moving_state(t_s: float, v_mps: float) -> dict:
    """The combine, tractor and cart side by side, all driving along the world's x at ``v_mps``."""
    x = v_mps * t_s
    state = {"t_s": t_s}
    for body, y in (("combine", 0.0), ("tractor", 12.0), ("cart", 7.0)):
        state.update({f"{body}_x_m": x, f"{body}_y_m": y, f"{body}_yaw_rad": 0.0})
    return state


def test_a_spout_camera_sees_the_ground_slide_and_the_cart_beside_it_still():
    """A camera on the combine looking straight down, the machines at 3.3 m/s for a 5 ms exposure: the ground at
    Z slides f v T / Z px along the image direction of the combine's forward axis; the cart, driving alongside at
    the same speed, and the combine's own auger do not move in the image."""
    from cosim.scenario.config.cameras import StereoCamera
    from cosim.world import labels as lb
    from renderer_proc.exposure import state_at, view_displacement

    spec = StereoCamera(kind="stereo_camera", profile="oak_d", motion_blur=True, exposure_ms=5.0,
                        mount={"parent": "combine", "xyz_m": [-2.0, 7.45, 6.0], "rpy_deg": [0.0, 90.0, -90.0]})
    pin = Pinhole(spec.width_px, spec.height_px, math.radians(spec.hfov_deg))
    v, z = 3.3, 6.0
    before, now = _moving_state(0.0, v), _moving_state(0.1, v)
    assert state_at(before, now, 0.095)["cart_x_m"] == pytest.approx(v * 0.095)
    depth = np.full((pin.height, pin.width), z, np.float32)
    label = np.full(depth.shape, lb.GROUND, np.uint8)
    label[:, : pin.width // 2] = lb.GRAIN
    label[:10] = lb.AUGER
    d = view_displacement(depth, label, pin, spec, np.eye(4), before, now)
    ground = np.hypot(d[10:, pin.width // 2:, 0], d[10:, pin.width // 2:, 1])
    assert np.allclose(ground, pin.f * v * 0.005 / z, atol=1e-3), (ground.min(), ground.max())
    assert np.abs(d[:, : pin.width // 2]).max() < 1e-3 and np.abs(d[:10]).max() < 1e-3


BLUR_RUN = """format_version: 1
name: blur_run
renderer: gl
duration_s: 0.3
feedback: perception
sensors:
  spout:
    kind: stereo_camera
    profile: oak_d
    every_frames: 1
    points_stride: 8
    mount: {parent: combine, xyz_m: [-2.0, 7.45, 6.0], rpy_deg: [0.0, 90.0, -90.0]}
"""


@pytest.mark.gl
def test_off_the_matcher_gets_the_renderers_bytes_and_on_the_moving_scene_blurs():
    """Off (the default), and on with an exposure too short to move a pixel by MIN_BLUR_PX, the stereo depth is
    the same to the byte; a 20 ms exposure changes it."""
    from cosim.runtime.inprocess import simulate
    from cosim.scenario.loader import load_scenario_text

    def depth(*sets: str) -> np.ndarray:
        s = load_scenario_text(BLUR_RUN, overrides=list(sets), check_world=True)
        return np.asarray(simulate(s).recorder.arrays["cam_spout_measured"])

    off = depth()
    assert load_scenario_text(BLUR_RUN).sensor_set["spout"].motion_blur is False
    assert np.array_equal(off, depth("sensors.spout.motion_blur=true", "sensors.spout.exposure_ms=0.0001"),
                          equal_nan=True)
    on = depth("sensors.spout.motion_blur=true", "sensors.spout.exposure_ms=20")
    assert not np.array_equal(off, on, equal_nan=True)
