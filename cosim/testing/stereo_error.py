"""The stereo depth error against its closed form dZ = Z^2 dd / (f B) on a rendered textured plane, for a stereo
camera's image formation switched on one at a time (perception_proc.cameras.imaging, docs/cameras.md; run by
bench/stereo_imaging.py and tests/test_camera_imaging.py).

The camera's whole depth path (perception_proc.cameras.stereo.stereo_depth: the matcher, texture gate, sub-pixel
refinement) on the formed images of a pair of :func:`cosim.testing.stereo_plane.textured_plane_pair`. Per variant:
the share of the plane's pixels at 3-9 m with a valid depth, the disparity error dd (px) fitted to the RMS depth
error per 1 m bin by least squares of RMS = dd Z^2 / (f B), the log-log slope of the RMS against Z, and the share of
valid pixels erring by more than 10 times the profile's stated sigma Z^2 disparity_sigma_px / (f B).
"""
from __future__ import annotations

import math

import numpy as np

from cosim.scenario.config.cameras import StereoCamera
from cosim.scenario.config.imaging import ImageNoise, LensDistortion
from cosim.world.camera import Pinhole
from perception_proc.cameras.imaging import ImageFormation
from perception_proc.cameras.stereo import make_matcher, stereo_depth

__all__ = ["CMV2000", "WIDE_LENS", "VARIANTS", "BINS", "FRAMES", "measure"]

#: shot and read noise of a machine-vision global-shutter sensor, the figures the ams (CMOSIS) CMV2000 datasheet
#: states for its 5.5 um pixel (full well 13.5 ke-, temporal read noise 13 e-)
CMV2000 = ImageNoise(full_well_e=13_500.0, read_noise_e=13.0)
#: a wide-angle lens's barrel distortion (OpenCV coefficients of the order a 70-90 deg lens calibrates to),
#: rectified from a calibration of 0.15 px RMS (the stereo pile-height study's, Sensors 2024 24(22):7204)
WIDE_LENS = LensDistortion(k1=-0.28, k2=0.07, p1=0.0005, p2=-0.0003, calibration_rms_px=0.15)
#: variant name -> the camera keys it sets
VARIANTS = {
    "ideal": {},
    "shot+read noise (CMV2000)": {"image_noise": CMV2000},
    "distortion, calibration 0.15 px": {"distortion": WIDE_LENS},
    "distortion, calibration 0.5 px": {"distortion": WIDE_LENS.model_copy(update={"calibration_rms_px": 0.5})},
    "noise + distortion 0.15 px": {"image_noise": CMV2000, "distortion": WIDE_LENS},
}
#: depth bins, m
BINS = np.arange(3.0, 9.0)
#: frames (noise draws) per variant
FRAMES = 3


def measure(cam: StereoCamera, pin: Pinhole, left: np.ndarray, right: np.ndarray, z: np.ndarray,
            frames: int = FRAMES) -> dict:
    """The variant's figures (module docstring) over ``frames`` noise draws of one rendered pair ``left``, ``right``
    (H, W, 4) uint8 with the left eye's exact planar depth ``z`` (H, W) m."""
    form = ImageFormation(cam, pin, seed=0, sensor_index=0)
    fb = pin.f * cam.baseline_m
    err, exact = [], []
    for frame in range(frames):
        a, b = (form.eye(left, 0, frame), form.eye(right, 1, frame)) if form.active else (left, right)
        d = stereo_depth(make_matcher(cam), cam, pin.f, a, b)
        err.append(d - z)
        exact.append(z)
    e, zz = np.concatenate([x.ravel() for x in err]), np.concatenate([x.ravel() for x in exact])
    inside = (zz >= BINS[0]) & (zz < BINS[-1] + 1.0)
    ok = inside & np.isfinite(e)
    rms = np.array([math.sqrt(float(np.mean(e[ok & (zz >= lo) & (zz < lo + 1)] ** 2))) for lo in BINS])
    law = (BINS + 0.5) ** 2 / fb
    gross = np.abs(e[ok]) > 10.0 * zz[ok] ** 2 * cam.disparity_sigma_px / fb
    return {"valid": float(ok.sum() / inside.sum()), "dd_px": float(np.sum(rms * law) / np.sum(law * law)),
            "slope": float(np.polyfit(np.log(BINS + 0.5), np.log(rms), 1)[0]), "gross": float(gross.mean()),
            "rms_mm": rms * 1e3}
