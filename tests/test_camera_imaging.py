"""A stereo camera's image formation against its closed forms (docs/cameras.md): EMVA 1288 shot and read noise,
Brown-Conrady distortion, rectification from a calibration with a stated residual; off, nothing changes."""
from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from cosim.errors import ScenarioError
from cosim.scenario.config.cameras import StereoCamera
from cosim.scenario.config.imaging import ImageNoise, LensDistortion
from cosim.scenario.loader import load_scenario_text
from cosim.testing.stereo_error import VARIANTS, measure
from cosim.testing.stereo_plane import textured_plane_pair
from cosim.world.camera import Pinhole
from perception_proc.cameras.imaging import (
    ImageFormation,
    calibration_error,
    calibration_generator,
    camera_matrix,
    coefficients,
    distort_points,
    distortion_maps,
    image_generator,
    rectification_maps,
    remap,
    shot_read_noise,
)

W, H, F = 320, 240, 250.0
K = camera_matrix(F, W, H)
LENS = LensDistortion(k1=-0.28, k2=0.07, p1=0.0008, p2=-0.0005, calibration_rms_px=0.15)
MOUNT = "{parent: combine, xyz_m: [-2.0, 7.6, 5.6], rpy_deg: [0.0, 90.0, 90.0]}"


@pytest.mark.parametrize("level, full_well, read", [(100, 10_000.0, 10.0), (30, 5_000.0, 0.0), (200, 2_000.0, 30.0)])
def test_shot_and_read_noise_has_the_photon_transfer_variance(level, full_well, read):
    """A flat image: mean p and variance K^2 (mu + read^2) + 1/12 grey levels^2, K = 255 / full_well, mu = p / K."""
    img = np.full((400, 400, 3), level, np.uint8)
    out = shot_read_noise(img, ImageNoise(full_well_e=full_well, read_noise_e=read), image_generator(0, 1, 0, 0))
    k = 255.0 / full_well
    var = k * k * (level / k + read * read) + 1.0 / 12.0
    assert float(np.mean(out)) == pytest.approx(level, abs=0.02)
    assert float(np.var(out.astype(np.float64))) == pytest.approx(var, rel=0.02)


def test_distorted_points_are_opencvs_projection():
    pts = np.array([[10.0, 7.0], [160.0, 120.0], [300.0, 230.0], [40.0, 200.0]])
    dist = coefficients(LENS)
    rays = np.stack([(pts[:, 0] - K[0, 2]) / F, (pts[:, 1] - K[1, 2]) / F, np.ones(4)], 1)
    cv, _ = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), K, dist)
    np.testing.assert_allclose(distort_points(pts, dist, K), cv.reshape(-1, 2), atol=1e-9)


def test_the_distortion_map_inverts_the_lens():
    """Every distorted pixel's ideal position, distorted again, lands back on that pixel (within 1e-3 px)."""
    mx, my = distortion_maps(coefficients(LENS), K, W, H)
    ideal = np.stack([mx.ravel(), my.ravel()], 1).astype(np.float64)
    uu, vv = np.meshgrid(np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64))
    back = distort_points(ideal, coefficients(LENS), K)
    assert np.max(np.abs(back - np.stack([uu.ravel(), vv.ravel()], 1))) < 1e-3


def _residual_px(lens: LensDistortion, err: np.ndarray) -> np.ndarray:
    """(N, 2) where each rectified pixel's content comes from in the ideal image, minus that pixel."""
    mx, my = rectification_maps(coefficients(lens) + err, K, W, H)
    seen = np.stack([mx.ravel(), my.ravel()], 1).reshape(-1, 1, 2).astype(np.float64)
    ideal = cv2.undistortPoints(seen, K, coefficients(lens), P=K,
                                criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-9)).reshape(-1, 2)
    uu, vv = np.meshgrid(np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64))
    return ideal - np.stack([uu.ravel(), vv.ravel()], 1)


def test_rectification_with_the_true_coefficients_is_the_identity():
    assert np.max(np.abs(_residual_px(LENS, np.zeros(4)))) < 0.01


@pytest.mark.parametrize("rms", [0.15, 0.5])
def test_rectification_carries_the_calibrations_residual(rms):
    """The perturbed calibration moves where each rectified pixel is taken from in the observed (distorted) image,
    where a calibration's reprojection residual is measured, by the stated RMS (OpenCV's maps, within 5 %); seeded.
    In the ideal image the residual is larger by the lens's local magnification (barrel: up to 1.5 here)."""
    lens = LENS.model_copy(update={"calibration_rms_px": rms})
    err = calibration_error(lens, K, W, H, calibration_generator(3, 0, 1))
    est = np.stack(rectification_maps(coefficients(lens) + err, K, W, H), -1).astype(np.float64)
    true = np.stack(rectification_maps(coefficients(lens), K, W, H), -1).astype(np.float64)
    assert float(np.sqrt(np.mean(np.sum((est - true) ** 2, -1)))) == pytest.approx(rms, rel=0.05)
    ideal = _residual_px(lens, err)
    assert rms < float(np.sqrt(np.mean(np.sum(ideal * ideal, 1)))) < 1.5 * rms
    again = calibration_error(lens, K, W, H, calibration_generator(3, 0, 1))
    other = calibration_error(lens, K, W, H, calibration_generator(3, 0, 0))
    assert np.array_equal(err, again) and not np.array_equal(err, other)


def test_a_lens_bends_straight_lines_and_rectification_straightens_them():
    """A vertical bright line near the image's edge: barrel distortion (k1 < 0) bows it (its column varies along the
    rows by over a pixel); rectified with the true coefficients it is straight again (within 0.4 px: two bilinear
    resamplings of a 3 px line in 8 bits)."""
    img = np.zeros((H, W, 3), np.uint8)
    img[:, 40:43] = 255
    lens = LENS.model_copy(update={"calibration_rms_px": 0.0})
    seen = remap(img, distortion_maps(coefficients(lens), K, W, H))
    back = remap(seen, rectification_maps(coefficients(lens), K, W, H))

    def centre(a):
        rows = range(20, H - 20)
        g = a[..., 0].astype(np.float64)
        return np.array([np.sum(g[r] * np.arange(W)) / np.sum(g[r]) for r in rows])

    assert np.ptp(centre(seen)) > 1.0 and np.ptp(centre(back)) < 0.4
    assert abs(float(np.mean(centre(back))) - 41.0) < 0.1


def test_off_means_no_formation_and_on_changes_only_the_colour():
    cam = StereoCamera(kind="stereo_camera", profile="oak_d", mount={"parent": "world"})
    assert cam.image_noise is None and cam.distortion is None
    on = cam.model_copy(update={"image_noise": ImageNoise(full_well_e=10_000.0, read_noise_e=5.0)})
    pin = Pinhole(cam.width_px, cam.height_px, math.radians(cam.hfov_deg))
    form = ImageFormation(on, pin, seed=0, sensor_index=0)
    img = np.full((cam.height_px, cam.width_px, 4), 120, np.uint8)
    out = form.eye(img, 0, 5)
    assert np.array_equal(out[..., 3], img[..., 3]) and not np.array_equal(out[..., :3], img[..., :3])
    assert np.array_equal(out, form.eye(img, 0, 5)) and not np.array_equal(out, form.eye(img, 1, 5))


@pytest.mark.parametrize("body, where, match", [
    ("    image_noise: {full_well_e: 100.0}\n", "sensors.s.image_noise.full_well_e", "greater than 500"),
    ("    image_noise: {read_noise_e: 2.0}\n", "sensors.s.image_noise.full_well_e", "missing"),
    ("    distortion: {k1: 3.0}\n", "sensors.s.distortion.k1", "less than or equal to 2"),
    ("    distortion: {calibration_rms_px: -0.1}\n", "sensors.s.distortion.calibration_rms_px", "greater than or"),
])
def test_bad_image_keys_are_reported_at_their_key(body, where, match):
    src = f"format_version: 1\nsensors:\n  s:\n    kind: stereo_camera\n{body}    mount: {MOUNT}\n"
    with pytest.raises(ScenarioError, match=match) as info:
        load_scenario_text(src, check_world=False)
    assert any(p.path == where for p in info.value.problems), [str(p) for p in info.value.problems]


@pytest.mark.gl
def test_noise_and_a_worse_calibration_raise_the_stereo_error(ctx):
    """The textured plane of cosim.testing.stereo_error (OAK-D pair, 3-9 m): the fitted disparity error of the ideal
    images is the matcher's (about 0.25 px); shot and read noise raise it, and a 0.5 px calibration more than a
    0.15 px one; the error still grows about as Z^2 (slope 2-3)."""
    base = StereoCamera(kind="stereo_camera", profile="oak_d", mount={"parent": "world"})
    pin = Pinhole(base.width_px, base.height_px, math.radians(base.hfov_deg))
    left, right, z = textured_plane_pair(ctx, pin, base.baseline_m)
    dd = {name: measure(base.model_copy(update=VARIANTS[name]), pin, left, right, z, frames=1)
          for name in ("ideal", "shot+read noise (CMV2000)", "distortion, calibration 0.15 px",
                       "distortion, calibration 0.5 px")}
    ideal = dd["ideal"]["dd_px"]
    assert 0.15 < ideal < 0.35
    assert dd["shot+read noise (CMV2000)"]["dd_px"] > 1.1 * ideal
    assert dd["distortion, calibration 0.5 px"]["dd_px"] > dd["distortion, calibration 0.15 px"]["dd_px"] > ideal
    assert all(1.8 < r["slope"] < 3.2 for r in dd.values()), {k: r["slope"] for k, r in dd.items()}
