"""A stereo camera's image formation (cosim.scenario.config.imaging, docs/cameras.md): the renderer's ideal
images -> what the head's matcher receives. Pure functions on (H, W, C) uint8 images, seeded.

In the order light meets them:

1. lens distortion (:func:`distortion_maps`, Brown-Conrady with OpenCV's k1, k2, p1, p2): each eye's image is the
   ideal pinhole image seen through its lens, ``cv2.remap`` at the ideal position of every distorted pixel
   (``cv2.undistortPoints``);
2. shot and read noise (:func:`shot_read_noise`, EMVA 1288's linear photon-transfer model): p grey levels hold
   mu = p full_well / 255 electrons; the pixel reads Poisson(mu) + Normal(0, read_noise^2) electrons, quantised
   back to 0-255 (each colour channel a pixel of its own);
3. rectification (:func:`rectification_maps`): the head undistorts each eye with the coefficients its calibration
   estimated, the true ones plus a perturbation (:func:`calibration_error`) in a random direction scaled so that it
   moves the image's pixels by the calibration's stated reprojection RMS; the rectified pair then differs from the
   ideal one by that residual (plus the interpolation of two remaps).

Generators: :func:`image_generator` (per frame and eye: the noise) and :func:`calibration_generator` (per camera
and eye, the same every frame: a calibration is done once).
"""
from __future__ import annotations

import cv2
import numpy as np

from cosim.scenario.config.imaging import ImageNoise, LensDistortion

__all__ = ["IMAGE_STREAM", "CALIBRATION_STREAM", "GREY_LEVELS", "image_generator", "calibration_generator",
           "shot_read_noise", "camera_matrix", "coefficients", "distort_points", "distortion_maps",
           "rectification_maps", "calibration_error", "remap", "ImageFormation"]

#: third seed word of the image-noise stream ("IMGN")
IMAGE_STREAM = 0x494D474E
#: third seed word of the calibration draw ("CALB")
CALIBRATION_STREAM = 0x43414C42
#: the largest pixel value of an 8-bit image
GREY_LEVELS = 255.0
#: grid step of the pixels the calibration's residual is measured on, px
RESIDUAL_GRID_PX = 8
#: coefficient step of the numerical derivative of the pixel positions
DERIVATIVE_STEP = 1e-6


def image_generator(seed: int, frame: int, sensor_index: int, eye: int) -> np.random.Generator:
    """The image-noise generator of one eye's frame: PCG64 seeded by (seed, frame, IMAGE_STREAM, index, eye)."""
    return np.random.default_rng([int(seed), int(frame), IMAGE_STREAM, int(sensor_index), int(eye)])


def calibration_generator(seed: int, sensor_index: int, eye: int) -> np.random.Generator:
    """The calibration draw of one eye: PCG64 seeded by (seed, CALIBRATION_STREAM, index, eye)."""
    return np.random.default_rng([int(seed), CALIBRATION_STREAM, int(sensor_index), int(eye)])


def shot_read_noise(img: np.ndarray, noise: ImageNoise, gen: np.random.Generator) -> np.ndarray:
    """``img`` (H, W, C) uint8 with shot and read noise (module docstring), a new (H, W, C) uint8 array."""
    per_level = noise.full_well_e / GREY_LEVELS                              # electrons per grey level
    electrons = gen.poisson(img.astype(np.float64) * per_level).astype(np.float64)
    if noise.read_noise_e > 0.0:
        electrons += gen.standard_normal(img.shape) * noise.read_noise_e
    return np.clip(np.rint(electrons / per_level), 0.0, GREY_LEVELS).astype(np.uint8)


def camera_matrix(focal_px: float, width: int, height: int) -> np.ndarray:
    """(3, 3) K of the pinhole (principal point at the image centre, pixel centres at +0.5)."""
    return np.array([[focal_px, 0.0, width / 2.0 - 0.5], [0.0, focal_px, height / 2.0 - 0.5], [0.0, 0.0, 1.0]])


def coefficients(lens: LensDistortion) -> np.ndarray:
    """(4,) OpenCV's distortion vector (k1, k2, p1, p2)."""
    return np.array([lens.k1, lens.k2, lens.p1, lens.p2], np.float64)


def distort_points(xy: np.ndarray, dist: np.ndarray, K: np.ndarray) -> np.ndarray:
    """(N, 2) pixel positions of the ideal pixels ``xy`` (N, 2) seen through a lens of coefficients ``dist`` (4,)
    (Brown-Conrady: r^2 = x^2 + y^2 of the normalised coordinates, x' = x (1 + k1 r^2 + k2 r^4) + 2 p1 x y +
    p2 (r^2 + 2 x^2), y' likewise with p1, p2 swapped)."""
    x = (xy[:, 0] - K[0, 2]) / K[0, 0]
    y = (xy[:, 1] - K[1, 2]) / K[1, 1]
    k1, k2, p1, p2 = dist
    r2 = x * x + y * y
    radial = 1.0 + k1 * r2 + k2 * r2 * r2
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    return np.stack([xd * K[0, 0] + K[0, 2], yd * K[1, 1] + K[1, 2]], axis=1)


def _grid(width: int, height: int, step: int = 1) -> np.ndarray:
    """(N, 2) float64 pixel positions (column, row) of every ``step``-th pixel."""
    uu, vv = np.meshgrid(np.arange(0, width, step, dtype=np.float64), np.arange(0, height, step, dtype=np.float64))
    return np.stack([uu.ravel(), vv.ravel()], axis=1)


def distortion_maps(dist: np.ndarray, K: np.ndarray, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """(map_x, map_y) (H, W) float32 for ``cv2.remap``: the ideal image's position of every pixel of the distorted
    image (``cv2.undistortPoints`` with the camera matrix as the new one)."""
    pts = _grid(width, height).reshape(-1, 1, 2)
    ideal = cv2.undistortPoints(pts, K, dist, P=K,
                                criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-6))
    ideal = ideal.reshape(height, width, 2).astype(np.float32)
    return ideal[..., 0], ideal[..., 1]


def rectification_maps(dist_est: np.ndarray, K: np.ndarray, width: int, height: int
                       ) -> tuple[np.ndarray, np.ndarray]:
    """(map_x, map_y) (H, W) float32 for ``cv2.remap``: the distorted image's position of every rectified pixel,
    by the estimated coefficients ``dist_est`` (``cv2.initUndistortRectifyMap``, the same camera matrix)."""
    return cv2.initUndistortRectifyMap(K, dist_est, None, K, (width, height), cv2.CV_32FC1)


def calibration_error(lens: LensDistortion, K: np.ndarray, width: int, height: int, gen: np.random.Generator
                      ) -> np.ndarray:
    """(4,) the calibration's error of the coefficients: a direction drawn from ``gen`` (standard normal in k1,
    k2, p1, p2), scaled so that the pixel positions it moves (every :data:`RESIDUAL_GRID_PX`-th pixel, to first
    order) move by ``lens.calibration_rms_px`` RMS; zeros when that is 0."""
    direction = gen.standard_normal(4)
    if lens.calibration_rms_px == 0.0:
        return np.zeros(4)
    dist = coefficients(lens)
    pts = _grid(width, height, RESIDUAL_GRID_PX)
    jac = np.stack([(distort_points(pts, dist + DERIVATIVE_STEP * e, K) - distort_points(pts, dist, K))
                    / DERIVATIVE_STEP for e in np.eye(4)], axis=-1)                    # (N, 2, 4) px per unit
    moved = jac @ direction
    rms = float(np.sqrt(np.mean(np.sum(moved * moved, axis=1))))
    return direction * (lens.calibration_rms_px / rms)


def remap(img: np.ndarray, maps: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """``img`` (H, W, C) uint8 resampled at ``maps`` (bilinear; outside the image: 0)."""
    return cv2.remap(img, maps[0], maps[1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)


class ImageFormation:
    """The image formation of stereo camera ``spec`` (a StereoCamera with ``image_noise`` and/or ``distortion``)
    at pinhole ``pin``, the ``sensor_index``-th sensor of a scenario of seed ``seed``: :meth:`apply` turns the
    eyes' ideal images into what the matcher receives (module docstring). The maps are computed once."""

    def __init__(self, spec, pin, seed: int, sensor_index: int):
        self.noise: ImageNoise | None = spec.image_noise
        self.lens: LensDistortion | None = spec.distortion
        self.seed, self.index = int(seed), int(sensor_index)
        w, h = pin.width, pin.height
        self.K = camera_matrix(pin.f, w, h)
        self.maps: list[tuple] = []
        if self.lens is not None:
            dist = coefficients(self.lens)
            seen = distortion_maps(dist, self.K, w, h)
            for eye in range(2):
                err = calibration_error(self.lens, self.K, w, h, calibration_generator(seed, sensor_index, eye))
                self.maps.append((seen, rectification_maps(dist + err, self.K, w, h)))

    @property
    def active(self) -> bool:
        """Whether anything changes the images."""
        return self.noise is not None or self.lens is not None

    def eye(self, img: np.ndarray, eye: int, frame: int) -> np.ndarray:
        """One eye's (H, W, 4) uint8 image (0 left, 1 right) of ring frame ``frame`` as the matcher receives it."""
        out = img.copy()
        rgb = np.ascontiguousarray(img[..., :3])
        if self.lens is not None:
            rgb = remap(rgb, self.maps[eye][0])
        if self.noise is not None:
            rgb = shot_read_noise(rgb, self.noise, image_generator(self.seed, frame, self.index, eye))
        if self.lens is not None:
            rgb = remap(rgb, self.maps[eye][1])
        out[..., :3] = rgb
        return out
