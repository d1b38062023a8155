"""The built-in perception's flying-pixel filter (perception_proc.cameras.jump_edges) on depth images from the
depth camera's own model: the mixed pixels at a rim's edge come out, the surfaces on both sides stay, and a
noisy or slanted surface loses (almost) nothing."""
from __future__ import annotations

import math

import numpy as np

from cosim.scenario.config.cameras import DepthCamera
from cosim.world.camera import Pinhole
from perception_proc.cameras.depth_models import normal_sigma_m
from perception_proc.cameras.jump_edges import flying_pixels, jump_threshold
from perception_proc.cameras.tof import frame_generator, tof_depth

PIN = Pinhole(256, 212, math.radians(70.6))
KINECT = DepthCamera(kind="depth_camera", mount={"parent": "world"}, range_max_m=10.0)


def _jump(z: np.ndarray, cam: DepthCamera = KINECT) -> np.ndarray:
    z = np.nan_to_num(np.asarray(z, np.float64), nan=1.0)
    return jump_threshold(z, normal_sigma_m(cam, z), PIN.f, cam.max_incidence_deg)


def _filtered(z: np.ndarray, cam: DepthCamera = KINECT) -> np.ndarray:
    return flying_pixels(z, _jump(z, cam))


def test_the_threshold_is_the_slope_over_two_pixels_plus_three_sigma():
    z = np.array([2.0, 5.0])
    expect = 2 * z * np.tan(np.radians(80.0)) / PIN.f + 3.0 * (0.0012 + 0.0019 * (z - 0.4) ** 2)
    np.testing.assert_allclose(_jump(z), expect, rtol=1e-12)


def test_a_band_between_two_surfaces_is_flying_and_the_surfaces_are_not():
    z = np.full((40, 40), 6.0, np.float32)            # grain behind
    z[:, :18] = 4.0                                   # the rim in front
    z[:, 18], z[:, 19] = 4.6, 5.3                     # two mixed pixels between them
    m = _filtered(z)
    assert m[:, 18:20].all()
    assert not m[:, :18].any() and not m[:, 20:].any()


def test_a_band_against_a_surface_out_of_range_is_flying():
    z = np.full((40, 40), np.nan, np.float32)         # grain beyond the camera's range
    z[:, :18] = 4.0
    z[:, 18:20] = 4.4
    m = _filtered(z)
    assert m[:, 18:20].all() and not m[:, :18].any()


def test_the_models_flying_pixels_at_a_rim_are_taken_out_and_the_surfaces_kept():
    """Exact depth: a rim at 4 m over grain at 6 m. The structured-light model mixes the pixels that straddle the
    step (uniform between the two depths) and adds its noise. After the filter, fewer than 1 % of the points
    farther than the threshold from both surfaces remain, while over 97 % of each surface's points stay."""
    exact = np.full((PIN.height, PIN.width), 6.0, np.float32)
    exact[:, : PIN.width // 2] = 4.0
    air = kept_air = rim = kept_rim = grain = kept_grain = 0
    for f in range(6):
        z = tof_depth(exact, PIN, KINECT, frame_generator(11, f, 0)).astype(np.float64)
        m, jump = _filtered(z), _jump(z)
        s4, s6 = 4.0 * normal_sigma_m(KINECT, 4.0), 4.0 * normal_sigma_m(KINECT, 6.0)
        between = (z > 4.0 + jump) & (z < 6.0 - jump)
        on_rim, on_grain = np.abs(z - 4.0) < s4, np.abs(z - 6.0) < s6
        air += between.sum()
        kept_air += (between & ~m).sum()
        rim += on_rim.sum()
        kept_rim += (on_rim & ~m).sum()
        grain += on_grain.sum()
        kept_grain += (on_grain & ~m).sum()
    assert air > PIN.height                           # the model does make flying pixels here
    assert kept_air < 0.01 * air, (kept_air, air)
    assert kept_rim > 0.97 * rim and kept_grain > 0.97 * grain


def test_a_noisy_plane_at_long_range_and_a_slanted_plane_lose_almost_nothing():
    far = np.full((PIN.height, PIN.width), 7.0, np.float32)
    z = tof_depth(far, PIN, KINECT, frame_generator(5, 0, 0)).astype(np.float64)
    ok = np.isfinite(z)
    assert _filtered(z)[ok].mean() < 0.005
    # a plane tilted 75 deg from the view axis, seen from 3 to 8 m: its depth changes smoothly, at up to about
    # 80 deg of incidence, the steepest the camera reports
    v = np.arange(PIN.height)[:, None] + 0.5 - PIN.height / 2.0
    slant = (4.0 / (1.0 - math.tan(math.radians(75.0)) * v / PIN.f)).astype(np.float32) * np.ones((1, PIN.width),
                                                                                                  np.float32)
    slant[(slant < 3.0) | (slant > 8.0)] = np.nan
    rows = np.flatnonzero(np.isfinite(slant[:, 0]))
    assert rows.size > 10
    assert not _filtered(slant)[rows[2:-2], 2:-2].any()


def test_the_strided_test_equals_the_whole_image_test_at_those_pixels():
    exact = np.full((PIN.height, PIN.width), 6.0, np.float32)
    exact[:, : PIN.width // 2] = 4.0
    z = tof_depth(exact, PIN, KINECT, frame_generator(2, 0, 0))
    jump = _jump(z)
    rows, cols = np.arange(1, PIN.height, 3), np.arange(1, PIN.width, 3)
    whole = flying_pixels(z, jump)
    np.testing.assert_array_equal(flying_pixels(z, jump[np.ix_(rows, cols)], rows, cols), whole[np.ix_(rows, cols)])
