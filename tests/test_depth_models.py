"""The depth camera's noise model against its closed form (Nguyen, Izadi and Lovell 2012) and the stereo camera's
error law dZ = Z^2 dd / (f B) on a rendered textured plane (docs/cameras.md)."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import norm

from cosim.scenario.config.cameras import DepthCamera, StereoCamera
from cosim.testing.stereo_plane import textured_plane_pair
from cosim.world.camera import Pinhole
from perception_proc.cameras.stereo import disparity, grey, make_matcher
from perception_proc.cameras.tof import axial_sigma, frame_generator, tof_depth

PIN = Pinhole(256, 212, math.radians(70.6))
TOF = DepthCamera(kind="depth_camera", mount={"parent": "world"}, range_max_m=10.0)


def test_defaults_are_the_papers_coefficients():
    z = np.array([1.0, 2.0, 3.0])
    np.testing.assert_allclose(axial_sigma(z, np.zeros(3), TOF), 0.0012 + 0.0019 * (z - 0.4) ** 2)


@pytest.mark.parametrize("z", [1.0, 2.0, 3.0])
def test_axial_sigma_of_a_plane_fits_the_model_within_ten_percent(z):
    """A fronto-parallel plane (incidence under 36 deg everywhere: the axial model's flat part; lateral noise
    reads the same depth): the fitted sigma of the reported depth is the model's 0.0012 + 0.0019 (z - 0.4)^2."""
    plane = np.full((PIN.height, PIN.width), z, np.float32)
    out = np.concatenate([tof_depth(plane, PIN, TOF, frame_generator(7, f, 0)).ravel() - z for f in range(4)])
    ok = np.isfinite(out)
    assert ok.mean() > 0.99
    model = 0.0012 + 0.0019 * (z - 0.4) ** 2
    fitted = float(np.std(out[ok]))
    assert abs(fitted / model - 1.0) < 0.10, (fitted, model)
    assert abs(float(np.mean(out[ok]))) < 0.05 * model


def test_lateral_noise_reads_across_a_depth_step_as_the_gaussian_says():
    """Left half at 2 m, right half at 3 m: a pixel two columns left of the step reads the far side when its
    horizontal displacement rounds to >= 2 (a draw >= 1.5 px): P = 1 - Phi(1.5 / sigma_L), sigma_L = 0.8 px at
    normal incidence; flying pixels (at the step itself) mix the two sides."""
    z = np.full((PIN.height, PIN.width), 2.0, np.float32)
    step = PIN.width // 2
    z[:, step:] = 3.0
    quiet = TOF.model_copy(update={"axial_a_m": 0.0, "axial_b_per_m": 0.0})       # no axial noise: exact reads
    frames = [tof_depth(z, PIN, quiet, frame_generator(3, f, 0)) for f in range(30)]
    col = np.concatenate([f[2:-2, step - 2] for f in frames])                  # away from the image's border
    far = float(np.mean(col > 2.5))
    expect = 1.0 - norm.cdf(1.5 / 0.8)
    assert abs(far / expect - 1.0) < 0.25, (far, expect)
    edge = np.concatenate([f[2:-2, step - 1] for f in frames])
    mixed = (edge > 2.0 + 1e-6) & (edge < 3.0 - 1e-6)
    assert mixed.mean() > 0.5 and np.all((edge[np.isfinite(edge)] >= 2.0) & (edge[np.isfinite(edge)] <= 3.0))


def test_grazing_pixels_are_invalid_and_the_draws_are_seeded():
    # a narrow camera (6 deg) and the plane X = Z / tan(87 deg) - 0.2 m: every pixel sees it at more than 84 deg
    # of incidence, beyond the 80 deg limit
    narrow = Pinhole(64, 48, math.radians(6.0))
    uu, _ = narrow.pixel_centres()
    z = (-0.2 / ((uu - narrow.width / 2.0) / narrow.f - 1.0 / math.tan(math.radians(87.0)))).astype(np.float32)
    z = np.where((z > 0.5) & (z < 10), z, np.nan).astype(np.float32)
    out = tof_depth(z, narrow, TOF, frame_generator(0, 0, 0))
    assert np.isfinite(z).sum() > 1000 and np.isfinite(out).mean() < 0.02
    plane = np.full((PIN.height, PIN.width), 2.0, np.float32)
    a, b = (tof_depth(plane, PIN, TOF, frame_generator(5, 9, 1)) for _ in range(2))
    assert np.array_equal(a, b, equal_nan=True)
    assert not np.array_equal(a, tof_depth(plane, PIN, TOF, frame_generator(5, 10, 1)), equal_nan=True)


@pytest.mark.gl
@pytest.mark.parametrize("matcher", ["sgbm", "bm"])
def test_stereo_depth_error_follows_z_squared_over_f_b(ctx, matcher):
    """A textured plane (the grain material) seen 40 deg down from 3 m by the OAK-D profile's pair: binned by
    the exact planar depth, the RMS depth error grows as Z^2 (log-log slope 2 +- 0.35), and each bin's
    disparity error dd = dZ f B / Z^2 stays within a factor 2.2 of the one fitted to dZ = dd Z^2 / (f B) over
    3-9 m (SGBM: dd = 0.26 px; BM: 0.18 px). Nothing is added to the images: the error is the matcher's."""
    cam = StereoCamera(kind="stereo_camera", profile="oak_d", mount={"parent": "world"}, matcher=matcher)
    pin = Pinhole(cam.width_px, cam.height_px, math.radians(cam.hfov_deg))
    img = textured_plane_pair(ctx, pin, cam.baseline_m)
    z = img[2]
    d = disparity(make_matcher(cam), grey(img[0]), grey(img[1]), cam.min_disparity_px)
    d[:, :cam.num_disparities] = np.nan                                     # no match is possible there
    fb = pin.f * cam.baseline_m
    zs, rms = [], []
    for lo in np.arange(3.0, 9.0):
        m = np.isfinite(d) & (z >= lo) & (z < lo + 1.0)
        assert m.sum() > 0.6 * ((z >= lo) & (z < lo + 1.0)).sum(), "the textured plane is matched"
        zs.append(lo + 0.5)
        rms.append(float(np.sqrt(np.mean((fb / d[m] - z[m]) ** 2))))
    zs, rms = np.array(zs), np.array(rms)
    law = zs**2 / fb
    dd = float(np.sum(rms * law) / np.sum(law * law))                       # least squares of rms = dd law
    slope = float(np.polyfit(np.log(zs), np.log(rms), 1)[0])
    assert 0.05 < dd < 0.5 and abs(slope - 2.0) < 0.35, (dd, slope, rms)
    per_bin = rms / law
    assert np.all((per_bin > dd / 2.2) & (per_bin < dd * 2.2)), (dd, per_bin)
