"""Dust in the cameras (perception_proc/atmosphere/camera.py through the post-process seam; docs/cameras.md,
docs/field.md): clear air changes nothing, the haze is Koschmieder's law, the speckle share is its closed form and
seeded, the depth camera's pixels go through the LiDAR's dust model, and the stereo matcher loses valid pixels as
the visibility drops."""
from __future__ import annotations

import math

import numpy as np
import pytest

from cosim.scenario.loader import load_scenario_text
from cosim.testing.stereo_plane import textured_plane_pair
from perception_proc.atmosphere.camera import (
    AIRLIGHT_RGB,
    CameraDust,
    hazed,
    speckle_generator,
    speckle_share,
    speckled,
)
from perception_proc.atmosphere.dust import hard_power, soft_power
from perception_proc.cameras.effects import NoEffects, camera_effects
from perception_proc.cameras.pipeline import CameraImages, CameraPipeline
from perception_proc.cameras.stereo import make_matcher, stereo_depth

TOF = """format_version: 1
name: tof_dust
renderer: gl
sensors:
  tof:
    kind: depth_camera
    profile: tof_kinect_class
    range_max_m: 8.0
    noise: false
    rgb: true
    mount: {parent: combine, xyz_m: [-3.5, 5.0, 6.0], rpy_deg: [0.0, 52.0, 116.0]}
"""
STEREO = """format_version: 1
name: stereo_dust
renderer: gl
sensors:
  st:
    kind: stereo_camera
    profile: oak_d
    mount: {parent: world}
"""


def _scenario(text: str, *overrides: str):
    return load_scenario_text(text, overrides=list(overrides))


def _plane(pipe: CameraPipeline, z: float) -> np.ndarray:
    return np.full((pipe.pin.height, pipe.pin.width), z, np.float32)


def test_clear_air_is_the_ideal_camera_and_a_gust_outside_its_window_changes_nothing():
    """No dust: the seam is NoEffects. Dust outside its window: the depth and images are byte-identical to
    clear air's; inside it they change."""
    clear = _scenario(TOF)
    assert isinstance(camera_effects(clear, "tof"), NoEffects)
    assert isinstance(camera_effects(_scenario(TOF, "atmosphere.stream_particles=true"), "tof"), NoEffects)
    gust = _scenario(TOF, "atmosphere.visibility_m=5.0", "atmosphere.dust_window_s=[10.0,20.0]")
    a, b = CameraPipeline(clear, "tof", 0), CameraPipeline(gust, "tof", 0)
    rgb = np.random.default_rng(1).integers(0, 256, (a.pin.height, a.pin.width, 4), dtype=np.uint8)
    images = CameraImages(3, rgb=rgb, depth=_plane(a, 6.0), t_s=9.9)
    za, zb = a.measure(images), b.measure(images)
    assert za.tobytes() == zb.tobytes()
    assert b.effects.images(images) is images
    inside = CameraImages(3, rgb=rgb, depth=_plane(a, 6.0), t_s=10.0)
    assert b.measure(inside).tobytes() != za.tobytes()
    assert not np.array_equal(b.effects.images(inside).rgb, rgb)


def test_haze_is_koschmieders_law_on_a_uniform_image():
    img = np.full((4, 5, 4), (40, 120, 250, 255), np.uint8)
    for t in (0.0, 0.37, 1.0):
        out = hazed(img, t)
        want = np.rint(np.array([40.0, 120.0, 250.0]) * t + np.array(AIRLIGHT_RGB) * (1.0 - t))
        assert np.all(out[..., :3] == want.astype(np.uint8)) and np.all(out[..., 3] == 255)
    tmap = np.linspace(0.0, 1.0, 20).reshape(4, 5)
    out = hazed(img, tmap).astype(float)
    np.testing.assert_allclose(out[..., 0], np.rint(40.0 * tmap + AIRLIGHT_RGB[0] * (1 - tmap)))


def test_the_depth_cameras_colour_image_is_hazed_by_each_pixels_range():
    """Per-pixel transmission exp(-alpha r), r the exact planar depth times the ray's length: a plane is hazed
    more at the image's corners than at its centre, each as the closed form says (speckle aside)."""
    s = _scenario(TOF, "atmosphere.visibility_m=20.0")
    pipe = CameraPipeline(s, "tof", 0)
    h, w = pipe.pin.height, pipe.pin.width
    img = np.zeros((h, w, 4), np.uint8)
    out = pipe.effects.images(CameraImages(0, rgb=img, depth=_plane(pipe, 5.0))).rgb
    alpha = math.log(20.0) / 20.0
    for v, u in ((h // 2, w // 2), (0, 0)):
        x, y = (u + 0.5 - w / 2) / pipe.pin.f, (h / 2 - v - 0.5) / pipe.pin.f
        t = math.exp(-alpha * 5.0 * math.sqrt(1 + x * x + y * y))
        assert out[v, u, 0] in (round(AIRLIGHT_RGB[0] * (1 - t)), round(AIRLIGHT_RGB[0])), (v, u)


def test_speckle_share_is_its_closed_form_and_seeded():
    share = speckle_share(0.6, 900.0)
    assert share == pytest.approx(1.0 - math.exp(-0.5 * 0.6 * 50e-6 * 900.0))
    img = np.zeros((400, 500, 4), np.uint8)
    share = 0.03
    out = speckled(img, share, speckle_generator(7, 3, 1))
    hit = np.all(out[..., :3] == np.asarray(AIRLIGHT_RGB, np.uint8), axis=-1)
    n = hit.size
    assert abs(hit.sum() - share * n) < 4.0 * math.sqrt(n * share * (1 - share))
    again = speckled(img, share, speckle_generator(7, 3, 1))
    assert again.tobytes() == out.tobytes()
    for other in (speckle_generator(7, 4, 1), speckle_generator(7, 3, 2), speckle_generator(7, 3, 1, 1)):
        assert speckled(img, share, other).tobytes() != out.tobytes()


def _detectable_range(alpha: float, rho: float, rho_min: float, r_max: float) -> float:
    """The range where (rho / pi) exp(-2 alpha R) / R^2 falls to the limit (rho_min / pi) / r_max^2 (bisection)."""
    lo, hi = 0.1, r_max
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if rho * math.exp(-2 * alpha * mid) / mid**2 >= rho_min / r_max**2 else (lo, mid)
    return lo


def test_tof_depth_through_dust_is_the_dust_model_on_a_plane():
    """Noise off, a plane at planar depth Z: in light dust (30 m, the dust's own return below the detection
    limit) the centre pixel reads Z while the plane is within the detectable range (closed form) and nothing
    beyond it; in dense dust the backscatter outshines the plane and the
    pixel reads the dust's peak range (an independent argmax of s(R))."""
    s = _scenario(TOF, "atmosphere.visibility_m=30.0", "sensors.tof.range_max_m=6.0")
    pipe = CameraPipeline(s, "tof", 0)
    a = s.atmosphere
    h, w = pipe.pin.height, pipe.pin.width
    c = (h // 2, w // 2)
    reach = _detectable_range(a.extinction_per_m, a.target_reflectivity, a.detection_reflectivity, 6.0)
    assert 4.0 < reach < 5.9                                   # clear air: the full 6 m
    for z, seen in ((reach - 0.1, True), (reach + 0.1, False)):
        d = pipe.measure(CameraImages(0, depth=_plane(pipe, z)))
        assert (d[c] == np.float32(z)) if seen else np.isnan(d[c]), (z, d[c])
    dense = _scenario(TOF, "atmosphere.visibility_m=10.0")
    pipe = CameraPipeline(dense, "tof", 0)
    ad = dense.atmosphere
    alpha = ad.extinction_per_m
    beta, tau = alpha / ad.lidar_ratio_sr, ad.pulse_half_power_ns * 1e-9
    z = 7.0
    r = np.arange(0.5, z, 0.005)
    sr = soft_power(r, alpha, beta, tau, *ad.overlap_m)
    p_min = hard_power(8.0, 0.0, ad.detection_reflectivity, 0.0, 0.0)
    assert sr.max() > max(hard_power(z, alpha, ad.target_reflectivity, 0.0, 0.0), p_min), "the backscatter wins"
    d = pipe.measure(CameraImages(0, depth=_plane(pipe, z)))
    assert float(d[c]) == pytest.approx(r[np.argmax(sr)], abs=0.02)
    assert 3.0 < float(d[c]) < 5.0 and np.all(d[np.isfinite(d)] < z)
    near = pipe.measure(CameraImages(0, depth=_plane(pipe, 2.0)))
    assert near[c] == np.float32(2.0), "a near plane outshines the dust"


@pytest.mark.gl
def test_the_stereo_matchers_correct_share_falls_as_the_visibility_drops(ctx):
    """A textured plane (the grain material) 40 deg down from 3 m seen by the OAK-D pair, rendered once; each
    visibility's images pass the seam (haze and speckle) to the matcher. The share of pixels with a depth within
    5 % of the exact one falls monotonically with the visibility, from clear air's (the ideal images') down to 2 m,
    and the wrong share among the valid rises down to 4 m: the matcher, not painted noise, fails on the degraded
    images. At 2 m and 1 m the images are flat and the texture check leaves next to nothing valid. Same scenario,
    same bytes."""
    clear = CameraPipeline(_scenario(STEREO), "st", 0)
    pin, cam = clear.pin, clear.spec
    img = textured_plane_pair(ctx, pin, cam.baseline_m)
    z = img[2]
    images = CameraImages(5, rgb=img[0], right=img[1])
    cols = slice(cam.min_disparity_px + cam.num_disparities, None)       # where a match is possible
    exact = z[:, cols]

    def shares(d):
        d = d[:, cols]
        valid = np.isfinite(d)
        with np.errstate(invalid="ignore"):
            ok = valid & (np.abs(d - exact) <= 0.05 * exact)
        return float(ok.mean()), float(1.0 - ok.sum() / max(valid.sum(), 1)), float(valid.mean())

    ideal = shares(stereo_depth(make_matcher(cam), cam, pin.f, img[0], img[1]))
    got = [shares(clear.measure(images))]
    assert got[0] == ideal and got[0][0] > 0.7, got
    for mor in (10.0, 4.0, 2.0, 1.0):
        pipe = CameraPipeline(_scenario(STEREO, f"atmosphere.visibility_m={mor}"), "st", 0)
        assert isinstance(pipe.effects, CameraDust)
        got.append(shares(pipe.measure(images)))
    correct, wrong = [g[0] for g in got[:-1]], [g[1] for g in got[:-2]]
    assert all(a > b + 0.005 for a, b in zip(correct, correct[1:])), got
    assert all(a < b for a, b in zip(wrong, wrong[1:])), got
    assert got[-1][2] < 0.01 and got[-2][2] < 0.05, "flat images come back invalid, not wrong"
    twice = [CameraPipeline(_scenario(STEREO, "atmosphere.visibility_m=4.0"), "st", 0).measure(images)
             for _ in range(2)]
    assert twice[0].tobytes() == twice[1].tobytes()


def test_a_run_applies_the_gust_by_the_frames_time():
    """In a run (mock renderer), a 20 m gust from 0.25 s: the depth camera's frames before it are the clear
    run's to the bit, from it the dust's return fills almost every pixel (false near where the surface is
    weaker, the sky included), and the same scenario twice gives the same series."""
    from cosim.runtime.inprocess import simulate

    text = TOF.replace("renderer: gl", "renderer: mock\nduration_s: 0.5")
    gust = ["atmosphere.visibility_m=20.0", "atmosphere.dust_window_s=[0.25,10.0]"]
    clear = simulate(load_scenario_text(text)).recorder.series()
    runs = [simulate(load_scenario_text(text, overrides=gust)).recorder.series() for _ in range(2)]
    t, before = runs[0]["sensor_tof.t_s"], runs[0]["sensor_tof.t_s"] < 0.25
    assert before.sum() == 3 and len(t) == 6
    vf, vc = runs[0]["sensor_tof.valid_fraction"], clear["sensor_tof.valid_fraction"]
    assert np.array_equal(vf[before], vc[before]) and np.all(vf[~before] > 0.99) and np.all(vc < 0.8)
    same = [np.array_equal(runs[0][k], runs[1][k], equal_nan=True) for k in runs[0] if not k.endswith("_ms")]
    assert all(same)                                                   # wall times aside
