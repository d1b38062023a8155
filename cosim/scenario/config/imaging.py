"""Scenario records of a stereo camera's image formation (``sensors.<name>.image_noise``, ``.distortion``): what a real sensor does to the image before the matcher sees it (perception_proc.cameras.imaging,
docs/cameras.md). Each is off (null) by default, and off the images are the renderer's, to the byte.

* :class:`ImageNoise`: photon transfer after EMVA 1288 (the standard for characterising machine-vision sensors):
  the pixel value is the signal's electrons over the full well, which draw Poisson shot noise, plus Gaussian read
  noise, quantised back to 8 bits;
* :class:`LensDistortion`: the Brown-Conrady model (k1, k2 radial, p1, p2 tangential, OpenCV's convention) of each
  lens, undone by rectification from a calibration whose coefficients carry the stated reprojection residual.
"""
from __future__ import annotations

from pydantic import Field

from .base import Model

__all__ = ["FULL_WELL_E", "DISTORTION_MAX", "ImageNoise", "LensDistortion"]

#: (smallest, largest) full-well capacity, electrons: from small-pixel phone sensors (~1 ke-) to large-pixel
#: machine-vision sensors (~100 ke-)
FULL_WELL_E = (500.0, 200_000.0)
#: largest magnitude of a Brown-Conrady coefficient (fisheye lenses go beyond what the polynomial model holds)
DISTORTION_MAX = 2.0


class ImageNoise(Model):
    """Shot and read noise at the scene's exposure (EMVA 1288's linear photon-transfer model): a pixel value p of 255
    is ``full_well_e`` electrons, so p holds mu = p full_well / 255 of them; the sensor reads Poisson(mu) plus a
    Gaussian of ``read_noise_e`` electrons and quantises to the nearest value (0-255). The variance in grey levels
    is K^2 (mu + read_noise^2) + 1/12, K = 255 / full_well."""

    full_well_e: float = Field(gt=FULL_WELL_E[0], le=FULL_WELL_E[1], allow_inf_nan=False)
    """Electrons at the largest pixel value (the sensor's saturation capacity at the scene's exposure), e-."""
    read_noise_e: float = Field(default=0.0, ge=0.0, le=1000.0, allow_inf_nan=False)
    """Temporal dark (read) noise, e- (1-sigma)."""


class LensDistortion(Model):
    """Brown-Conrady lens distortion (OpenCV's k1, k2, p1, p2 on normalised image coordinates) of each eye, and its
    rectification from a calibration with reprojection residual ``calibration_rms_px``: each eye is rectified with
    coefficients perturbed from the true ones in a random direction (seeded per camera and eye, fixed for the run),
    scaled so that the perturbation moves the image's pixels by ``calibration_rms_px`` RMS."""

    k1: float = Field(default=0.0, ge=-DISTORTION_MAX, le=DISTORTION_MAX, allow_inf_nan=False)
    """First radial coefficient (OpenCV's k1)."""
    k2: float = Field(default=0.0, ge=-DISTORTION_MAX, le=DISTORTION_MAX, allow_inf_nan=False)
    """Second radial coefficient (OpenCV's k2)."""
    p1: float = Field(default=0.0, ge=-0.1, le=0.1, allow_inf_nan=False)
    """First tangential coefficient (OpenCV's p1)."""
    p2: float = Field(default=0.0, ge=-0.1, le=0.1, allow_inf_nan=False)
    """Second tangential coefficient (OpenCV's p2)."""
    calibration_rms_px: float = Field(default=0.0, ge=0.0, le=5.0, allow_inf_nan=False)
    """Reprojection RMS of the calibration that rectifies the images, px (0: the true coefficients)."""
