"""The depth camera's models named for what they model (docs/cameras.md): the time-of-flight model against its
closed forms (amplitude-dependent noise on planes at known range and incidence, mixed pixels only at depth edges and
between the two surfaces), the dispatch by ``model``, and the renamed profile's old name."""
from __future__ import annotations

import math

import numpy as np
import pytest

from cosim.errors import ScenarioError
from cosim.scenario.config.cameras import DepthCamera
from cosim.scenario.config.profiles import RENAMED, load_profile
from cosim.scenario.loader import load_scenario_text
from cosim.world.camera import Pinhole
from perception_proc.cameras.depth_models import depth_model, normal_sigma_m
from perception_proc.cameras.expected import point_sigma_m
from perception_proc.cameras.multipath import multipath_range_bias, pixel_range_bias
from perception_proc.cameras.time_of_flight import (
    amplitude,
    mixed_depth,
    ray_length_factor,
    time_of_flight_depth,
    tof_sigma_m,
)
from perception_proc.cameras.tof import flying_mask, frame_generator, incidence, tof_depth

PIN = Pinhole(200, 160, math.radians(60.0))
MOUNT = "{parent: combine, xyz_m: [-2.0, 7.6, 5.6], rpy_deg: [0.0, 90.0, 90.0]}"
TOF = DepthCamera(kind="depth_camera", mount={"parent": "world"}, profile="azure_kinect_nfov", range_max_m=20.0)


def test_the_reference_return_has_the_datasheet_sigma_and_the_law_has_both_terms():
    """At the reference (15 % reflectance at 3.86 m, facing) sigma is the datasheet's 17 mm; at a quarter of its
    amplitude sigma = 17 mm sqrt(s 4 + (1 - s) 16)."""
    assert TOF.model == "time_of_flight" and TOF.profile == "azure_kinect_nfov"
    ref = amplitude(np.array(3.86), np.array(0.0), 0.15)
    assert float(tof_sigma_m(ref, TOF)) == pytest.approx(0.017, rel=1e-12)
    s = TOF.tof_signal_share
    assert float(tof_sigma_m(ref / 4.0, TOF)) == pytest.approx(0.017 * math.sqrt(4 * s + 16 * (1 - s)), rel=1e-12)
    dark = TOF.model_copy(update={"albedo": 0.15})
    assert float(normal_sigma_m(dark, 3.86)) == pytest.approx(0.017, rel=1e-12)
    assert float(point_sigma_m(dark, 500.0, 3.86)) == pytest.approx(0.017, rel=1e-12)


def test_the_binned_mode_is_the_datasheets_and_carries_17_mm_to_its_own_range_end():
    """NFOV 2x2 binned: 320 x 288, the unbinned field, 0.5-5.46 m; sigma at its reference (15 % at 5.46 m, facing)
    is 17 mm, and at albedo 0.3 a facing surface at 5.46 m has what the unbinned mode has at 3.86 m (the same
    amplitude ratio to each mode's reference)."""
    binned = DepthCamera(kind="depth_camera", mount={"parent": "world"}, profile="azure_kinect_nfov_binned")
    unbinned = DepthCamera(kind="depth_camera", mount={"parent": "world"}, profile="azure_kinect_nfov")
    assert (binned.width_px, binned.height_px, binned.hfov_deg) == (320, 288, unbinned.hfov_deg)
    assert (binned.range_min_m, binned.range_max_m, binned.model) == (0.5, 5.46, "time_of_flight")
    assert binned.focal_px == pytest.approx(unbinned.focal_px / 2.0, rel=1e-12)
    ref = amplitude(np.array(5.46), np.array(0.0), 0.15)
    assert float(tof_sigma_m(ref, binned)) == pytest.approx(0.017, rel=1e-12)
    assert float(normal_sigma_m(binned, 5.46)) == pytest.approx(float(normal_sigma_m(unbinned, 3.86)), rel=1e-12)
    values = load_profile("azure_kinect_nfov_binned").values
    assert all(values[k].source == "datasheet" for k in ("width_px", "height_px", "hfov_deg", "range_max_m"))


def _plane(normal_cam: np.ndarray, d: float) -> np.ndarray:
    """Planar depth (H, W) of the plane n . p = d seen by PIN (n in the camera frame X right, Y up, Z forward)."""
    uu, vv = PIN.pixel_centres()
    x, y = (uu - PIN.width / 2.0) / PIN.f, (PIN.height / 2.0 - vv) / PIN.f
    return (d / (normal_cam[0] * x + normal_cam[1] * y + normal_cam[2])).astype(np.float32)


@pytest.mark.parametrize("z, tilt_deg", [(1.5, 0.0), (3.0, 0.0), (3.0, 50.0), (6.0, 30.0)])
def test_noise_on_a_plane_is_the_amplitude_law(z, tilt_deg):
    """A plane at planar depth z on the axis, turned tilt_deg about the image's vertical: every pixel's residual
    divided by the law's sigma (range sigma at albedo cos(theta) / r^2, over the ray's length per unit depth) has
    unit standard deviation and zero mean; the incidence and range come from the geometry, not from the model. (Where
    the slant makes neighbouring pixels differ by more than ``flying_edge_m`` they count as mixed pixels: left out.)"""
    t = math.radians(tilt_deg)
    n = np.array([math.sin(t), 0.0, math.cos(t)])
    exact = _plane(n, z * math.cos(t))
    k = ray_length_factor(PIN)
    uu, vv = PIN.pixel_centres()
    ray = np.stack([(uu - PIN.width / 2.0) / PIN.f, (PIN.height / 2.0 - vv) / PIN.f, np.ones_like(uu)], -1)
    cos = np.abs(ray @ n) / np.linalg.norm(ray, axis=-1)
    sigma_z = tof_sigma_m(TOF.albedo * cos / (exact * k) ** 2, TOF) / k
    keep = ~flying_mask(exact, TOF.flying_edge_m)[0][2:-2, 2:-2].ravel()
    assert keep.mean() > 0.7
    res = np.concatenate([((time_of_flight_depth(exact, PIN, TOF, frame_generator(5, f, 0)) - exact) / sigma_z)
                          [2:-2, 2:-2].ravel()[keep] for f in range(3)])
    ok = np.isfinite(res)
    assert ok.mean() > 0.999
    assert abs(float(np.std(res[ok])) - 1.0) < 0.02, float(np.std(res[ok]))
    assert abs(float(np.mean(res[ok]))) < 0.02


def test_a_darker_farther_surface_is_noisier_by_the_law():
    """Facing plane: sigma at (r, albedo) over sigma at (2 r, albedo / 2) is the law's ratio (q grows 8 times)."""
    near = normal_sigma_m(TOF, 2.0)
    far = normal_sigma_m(TOF.model_copy(update={"albedo": TOF.albedo / 2}), 4.0)
    q = TOF.tof_ref_albedo / TOF.tof_ref_range_m ** 2 / (TOF.albedo / 4.0)
    s = TOF.tof_signal_share
    assert far / near == pytest.approx(math.sqrt(s * 8 * q + (1 - s) * 64 * q * q) / math.sqrt(s * q + (1 - s) * q * q))


def test_mixed_depth_is_the_amplitude_weighted_mean():
    """Near 2 m, far 4 m, half the footprint on each: amplitudes 1 and 1/4: (0.5 2 + 0.125 4) / 0.625 = 2.4 m;
    no return behind: the near depth at half its amplitude."""
    d, a = mixed_depth(np.array([2.0, 2.0]), np.array([4.0, np.nan]), np.array([0.5, 0.5]))
    np.testing.assert_allclose(d, [2.4, 2.0])
    np.testing.assert_allclose(a, [0.625, 0.5])


def test_mixed_pixels_appear_only_at_depth_edges_and_lie_between_the_surfaces():
    """Left half at 2 m, right half at 3.5 m, the law's noise made negligible: every pixel off its exact depth by
    more than 1 mm is within one column of the step and reads between 2 and 3.5 m; most pixels there are mixed."""
    z = np.full((PIN.height, PIN.width), 2.0, np.float32)
    step = PIN.width // 2
    z[:, step:] = 3.5
    quiet = TOF.model_copy(update={"tof_ref_sigma_m": 1e-9})
    outs = [time_of_flight_depth(z, PIN, quiet, frame_generator(9, f, 0)) for f in range(5)]
    for out in outs:
        off = np.abs(out - z) > 1e-3
        rows, cols = np.nonzero(off)
        assert set(cols.tolist()) <= {step - 1, step}
        assert np.all((out[off] > 2.0) & (out[off] < 3.5))
    edge = np.stack([o[:, step - 1:step + 1] for o in outs])
    assert np.mean(np.abs(edge - z[None, :, step - 1:step + 1]) > 1e-3) > 0.9


def _whole_image_reference(z, pin, cam, gen):
    """The model written over the whole image (each return's amplitude from :func:`amplitude`, the mixture
    computed everywhere and chosen on the edge pixels): the readable form the kernel is checked against."""
    z = np.asarray(z, np.float64)
    theta = np.nan_to_num(incidence(pin, z), nan=0.0)
    k = ray_length_factor(pin)
    fly, near, far = flying_mask(z, cam.flying_edge_m)
    mixed, weight = mixed_depth(near, far, gen.random(z.shape))
    out = np.where(fly, mixed, z)
    amp = np.where(fly, amplitude(near * k, theta, cam.albedo) * weight, amplitude(z * k, theta, cam.albedo))
    out = out + gen.standard_normal(z.shape) * (tof_sigma_m(amp, cam) / k)
    with np.errstate(invalid="ignore"):
        bad = ~np.isfinite(out) | (out < cam.range_min_m) | (out > cam.range_max_m) | (
            incidence(pin, z) > math.radians(cam.max_incidence_deg))
    out[bad] = np.nan
    return out.astype(np.float32)


@pytest.mark.parametrize("seed", [0, 1])
def test_the_model_equals_its_whole_image_reference_to_the_bit(seed):
    """A floor, a box in front of it (depth edges), sky and single missing pixels: the kernel, which mixes the
    returns of the edge pixels only, gives the whole-image form's bytes."""
    rng = np.random.default_rng(seed)
    v = np.arange(PIN.height)[:, None] + 0.5
    z = 2.5 + 30.0 / np.maximum(v, 4.0) + 0.002 * rng.standard_normal((PIN.height, PIN.width))
    z[40:90, 60:140] = 2.0 + 0.01 * np.arange(80)[None, :]
    z[:8] = np.nan
    z[rng.integers(0, PIN.height, 20), rng.integers(0, PIN.width, 20)] = np.nan
    z = z.astype(np.float32)
    got = time_of_flight_depth(z, PIN, TOF, frame_generator(seed, 3, 0))
    want = _whole_image_reference(z, PIN, TOF, frame_generator(seed, 3, 0))
    assert flying_mask(np.asarray(z, np.float64), TOF.flying_edge_m)[0].mean() > 0.01
    assert 0.5 < np.isfinite(got).mean() and got.tobytes() == want.tobytes()


def test_without_noise_the_exact_depth_within_the_limits():
    z = np.full((PIN.height, PIN.width), 2.0, np.float32)
    z[:10] = 30.0
    out = time_of_flight_depth(z, PIN, TOF, None)
    assert np.all(np.isnan(out[:10])) and np.array_equal(out[10:], z[10:])


def test_the_model_key_picks_the_function_and_defaults_to_structured_light():
    sl = DepthCamera(kind="depth_camera", mount={"parent": "world"})
    assert sl.model == "structured_light" and depth_model(sl) is tof_depth
    assert depth_model(TOF) is time_of_flight_depth
    assert normal_sigma_m(sl, 3.0) == pytest.approx(0.0012 + 0.0019 * 2.6 ** 2)


def test_the_old_profile_name_loads_the_same_model_under_its_true_name():
    assert RENAMED["tof_kinect_class"] == "kinect_class_structured_light"
    old = DepthCamera(kind="depth_camera", mount={"parent": "world"}, profile="tof_kinect_class")
    new = DepthCamera(kind="depth_camera", mount={"parent": "world"}, profile="kinect_class_structured_light")
    assert old == new and old.profile == "kinect_class_structured_light" and old.model == "structured_light"
    assert load_profile("tof_kinect_class").name == "kinect_class_structured_light"
    v1 = DepthCamera(kind="depth_camera", mount={"parent": "world"}, profile="kinect_v1_structured_light")
    assert (v1.width_px, v1.height_px, v1.hfov_deg, v1.model) == (640, 480, 57.0, "structured_light")


@pytest.mark.parametrize("body, where, match", [
    ("    model: lidar_like\n", "sensors.t.model", "structured_light"),
    ("    albedo: 1.5\n", "sensors.t.albedo", "less than or equal to 1"),
    ("    tof_signal_share: -0.1\n", "sensors.t.tof_signal_share", "greater than or equal to 0"),
    ("    tof_ref_range_m: 0.0\n", "sensors.t.tof_ref_range_m", "greater than 0"),
])
def test_bad_time_of_flight_keys_are_reported_at_their_key(body, where, match):
    src = f"format_version: 1\nsensors:\n  t:\n    kind: depth_camera\n{body}    mount: {MOUNT}\n"
    with pytest.raises(ScenarioError, match=match) as info:
        load_scenario_text(src, check_world=False)
    assert any(p.path == where for p in info.value.problems), [str(p) for p in info.value.problems]


def test_multipath_of_two_patches_is_the_one_bounce_closed_form():
    """Two patches facing each other across a corner: patch 0 on the floor (normal up, towards the camera side),
    patch 1 on a wall; the bias of patch 1 is (E1 r1 + E01 (r0 + d + r1) / 2) / (E1 + E01) - r1 with
    E = cos / r^2 and E01 = albedo E0 a0 cos_out cos_in / (pi d^2)."""
    p = np.array([[0.0, -1.0, 3.0], [0.0, 0.0, 4.0]])
    n = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, -1.0]])
    a = np.array([0.04, 0.04])
    r = np.linalg.norm(p, axis=1)
    e = np.abs(np.sum(n * p, 1)) / r ** 3
    dvec = p[0] - p[1]
    d = np.linalg.norm(dvec)
    u = dvec / d                                              # from patch 1 towards patch 0
    e01 = 0.5 * e[0] * a[0] * float(-u @ n[0]) * float(u @ n[1]) / (math.pi * d * d)
    e10 = 0.5 * e[1] * a[1] * float(u @ n[1]) * float(-u @ n[0]) / (math.pi * d * d)
    half = (r[0] + d + r[1]) / 2.0
    want = [(e[0] * r[0] + e10 * half) / (e[0] + e10) - r[0], (e[1] * r[1] + e01 * half) / (e[1] + e01) - r[1]]
    np.testing.assert_allclose(multipath_range_bias(p, n, a, 0.5), want, rtol=1e-12)
    assert all(w > 0 for w in want)


def _fold(depth_at_centre: float, slope: float) -> np.ndarray:
    """Planar depth of the two planes Z = c + slope |X| meeting along the image's vertical centre line: z = c /
    (1 - slope |x|), x the normalised image column (slope > 0: the centre line nearest, a ridge; < 0: the centre
    line farthest, a corner seen from inside)."""
    uu, _ = PIN.pixel_centres()
    x = (uu - PIN.width / 2.0) / PIN.f
    return (depth_at_centre / (1.0 - slope * np.abs(x))).astype(np.float32)


def test_multipath_is_nil_on_a_plane_and_on_a_ridge_and_reads_a_corner_farther():
    flat = np.full((PIN.height, PIN.width), 3.0, np.float32)
    assert np.max(np.abs(pixel_range_bias(PIN, flat, 0.5))) < 1e-9
    ridge = _fold(3.0, 0.8)                         # the centre line nearest: the two halves face away
    assert np.max(np.abs(pixel_range_bias(PIN, ridge, 0.5))) < 1e-9
    corner = _fold(3.0, -0.8)                       # the centre line farthest: the halves face each other
    bias = pixel_range_bias(PIN, corner, 0.5)
    assert np.all(bias > 1e-3) and np.all(bias < 0.1), (bias.min(), bias.max())
    darker = pixel_range_bias(PIN, corner, 0.1)
    assert np.all(darker < bias / 3.0), "the detours' weight is proportional to the albedo"


def test_multipath_on_moves_the_reported_depth_by_the_bias():
    corner = _fold(3.0, -0.8)
    on = TOF.model_copy(update={"multipath": True, "tof_ref_sigma_m": 1e-9})
    off = on.model_copy(update={"multipath": False})
    k = ray_length_factor(PIN)
    got = time_of_flight_depth(corner, PIN, on, frame_generator(1, 0, 0)).astype(np.float64)
    base = time_of_flight_depth(corner, PIN, off, frame_generator(1, 0, 0)).astype(np.float64)
    want = pixel_range_bias(PIN, corner, TOF.albedo) / k
    ok = np.isfinite(got) & np.isfinite(base)
    np.testing.assert_allclose((got - base)[ok], want[ok], atol=2e-6)
    assert TOF.multipath is False
