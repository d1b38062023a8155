"""Rig planning: coverage of the LiDAR pattern with the promised nearest-pixel error, fewest cameras."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cosim.scenario.config import Scenario
from cosim.world.rig import (
    MAX_FOV_DEG,
    beam_angles,
    beam_pixel_error,
    plan_cameras,
    plan_rig,
    required_focal_px,
    scale_rig,
)


def grid(az0, az1, el0, el1, n_az=61, n_el=41):
    e, a = np.meshgrid(np.radians(np.linspace(el0, el1, n_el)), np.radians(np.linspace(az0, az1, n_az)),
                       indexing="ij")
    return e.ravel(), a.ravel()


def scenario(**kw) -> Scenario:
    return Scenario.model_validate({"format_version": 1, **kw})


def test_required_focal_closed_form():
    assert required_focal_px(math.radians(0.1)) == pytest.approx(math.sqrt(0.5) / math.sin(math.radians(0.1)))
    with pytest.raises(ValueError, match="max angular error"):
        required_focal_px(0.0)


@settings(max_examples=25, deadline=None)
@given(st.floats(-80.0, 0.0), st.floats(5.0, 170.0), st.floats(-60.0, 0.0), st.floats(3.0, 100.0),
       st.floats(0.05, 0.5))
def test_planned_rig_covers_with_promised_error(az0, az_span, el0, el_span, err_deg):
    el, az = grid(az0, min(az0 + az_span, 180.0), el0, min(el0 + el_span, 75.0))
    rig = plan_cameras(el, az, math.radians(err_deg))
    err, cam = beam_pixel_error(rig, el, az)
    assert np.all(cam >= 0), "every beam lies inside some camera"
    assert err.max() <= math.radians(err_deg) * (1 + 1e-9)
    for c in rig.cameras:
        assert c.intrinsics.f >= required_focal_px(math.radians(err_deg)) * (1 - 1e-9)
        assert math.degrees(c.intrinsics.hfov_rad) <= MAX_FOV_DEG + 1e-9
        assert math.degrees(c.intrinsics.vfov_rad) <= MAX_FOV_DEG + 1e-9
    assert [c.name for c in rig.cameras] == [f"cam{k}" for k in range(len(rig))]


def test_fewest_cameras_and_smallest_size():
    el, az = grid(-30.0, 30.0, -10.0, 10.0)
    rig = plan_cameras(el, az, math.radians(0.1))
    assert len(rig) == 1
    f = required_focal_px(math.radians(0.1))
    cam = rig.cameras[0].intrinsics
    # symmetric pattern, one camera looking at its centre: w = ceil(2 f tan 30), h = ceil(2 f tan 10 / cos 30)
    assert cam.width == math.ceil(2 * f * math.tan(math.radians(30)))
    assert cam.height == math.ceil(2 * f * math.tan(math.radians(10)) / math.cos(math.radians(30)))
    err, k = beam_pixel_error(rig, el, az)
    assert np.all(k == 0)


def test_wide_pattern_needs_stitched_cameras():
    """The paper stitches two cameras: 180 deg of azimuth exceeds one camera's MAX_FOV_DEG."""
    el, az = grid(-90.0, 90.0, -10.0, 10.0)
    rig = plan_cameras(el, az, math.radians(0.2))
    assert len(rig) == 2
    yaws = sorted(math.degrees(math.atan2(-c.sensor_from_camera[0, 2], c.sensor_from_camera[2, 2]))
                  for c in rig.cameras)
    assert yaws == pytest.approx([-45.0, 45.0])


def test_tall_pattern_uses_pitched_rows():
    el, az = grid(-10.0, 10.0, -80.0, 80.0)
    rig = plan_cameras(el, az, math.radians(0.2))
    assert len(rig) == 2
    pitches = sorted(math.degrees(math.asin(c.sensor_from_camera[1, 2])) for c in rig.cameras)
    assert pitches == pytest.approx([-40.0, 40.0])
    err, k = beam_pixel_error(rig, el, az)
    assert np.all(k >= 0) and err.max() <= math.radians(0.2)


def test_impossible_pattern_is_refused():
    el, az = grid(-179.0, 179.0, -89.0, 89.0, 40, 40)
    with pytest.raises(ValueError, match="no rig of"):
        plan_cameras(el, az, math.radians(0.001))


def test_default_scenario_rig_covers_pattern():
    s = Scenario(format_version=1)
    rig = plan_rig(s)
    el, az = beam_angles(s.sensor.pattern)
    err, k = beam_pixel_error(rig, el, az)
    assert np.all(k >= 0)
    assert math.degrees(err.max()) <= s.sensor.max_angular_error_deg


def test_fixed_rig_and_mock_scale():
    s = scenario(render={"rig": "fixed", "cameras": 2, "width_px": 320, "height_px": 200, "hfov_deg": 50.0})
    rig = plan_rig(s)
    assert [(c.intrinsics.width, c.intrinsics.height) for c in rig.cameras] == [(320, 200), (320, 200)]
    # neighbours touch: yaw step = hfov
    y = [math.atan2(-c.sensor_from_camera[0, 2], c.sensor_from_camera[2, 2]) for c in rig.cameras]
    assert math.degrees(y[1] - y[0]) == pytest.approx(50.0)
    m = scenario(renderer="mock", render={"rig": "fixed", "cameras": 1, "width_px": 320, "height_px": 200,
                                          "mock_scale": 0.5})
    cam = plan_rig(m).cameras[0].intrinsics
    assert (cam.width, cam.height) == (160, 100)
    assert cam.hfov_rad == pytest.approx(math.radians(60.0))
    assert scale_rig(rig, 1.0) is rig
