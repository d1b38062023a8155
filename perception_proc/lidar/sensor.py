"""Range limits, the noise model and the point-cloud record of the simulated LiDAR.

Noise (``cosim.scenario.config.Noise``): every valid return gets Gaussian range noise of ``range_sigma_m`` along its
beam, and each beam independently drops out with probability ``dropout``. The generator is seeded from the
scenario seed and the frame id (:func:`frame_generator`), so a run is reproducible frame by frame whatever
order frames are computed in. Limits (``Sensor.range_min_m`` / ``range_max_m``) apply to the noisy range;
returns outside them are invalid (NaN), never clamped.
"""
from __future__ import annotations

import cv2
import numpy as np

from cosim.scenario.config import Sensor

__all__ = ["frame_generator", "apply_noise_and_limits", "to_points", "to_points_reference", "point_basis", "NOISE_STREAM"]

#: fixed third seed word that separates the LiDAR noise stream from any other use of (seed, frame)
NOISE_STREAM = 0x4C494441  # "LIDA"


def frame_generator(seed: int, frame: int) -> np.random.Generator:
    """The noise generator of one frame: PCG64 seeded by (seed, frame, NOISE_STREAM)."""
    if frame < 0:
        raise ValueError(f"frame must be >= 0, got {frame}")
    return np.random.default_rng([int(seed), int(frame), NOISE_STREAM])


def apply_noise_and_limits(ranges: np.ndarray, sensor: Sensor, gen: np.random.Generator | None) -> np.ndarray:
    """Noisy, range-limited ranges (N,) float32, m, NaN where invalid; ``ranges`` (N,) float32 is updated in
    place and returned. ``gen`` None applies the limits only (no noise, no dropout)."""
    r = ranges
    noise = sensor.noise
    if gen is not None and noise.range_sigma_m > 0.0:
        r += gen.standard_normal(r.shape[0], dtype=np.float32) * np.float32(noise.range_sigma_m)
    if gen is not None and noise.dropout > 0.0:
        r[gen.random(r.shape[0], dtype=np.float32) < np.float32(noise.dropout)] = np.nan
    with np.errstate(invalid="ignore"):
        out = (r < np.float32(sensor.range_min_m)) | (r > np.float32(sensor.range_max_m))
    r[out] = np.nan
    return r


def point_basis(directions: np.ndarray) -> np.ndarray:
    """(N, 4) float32 C-contiguous rows (s_x, s_y, s_z, 1) of unit beams ``directions`` (N, 3), sensor frame:
    the ``lidar_points`` record is then this times the range, in float32 (see :func:`to_points`)."""
    d = np.asarray(directions, np.float32)
    return np.ascontiguousarray(np.concatenate([d, np.ones((d.shape[0], 1), np.float32)], axis=1))


def to_points(directions: np.ndarray, ranges: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """The ``lidar_points`` record: (N, 4) float32 rows x, y, z (sensor frame, m), range (m); NaN rows where
    the range is NaN. ``directions`` (N, 3) unit beams, sensor frame, or their :func:`point_basis` (N, 4)
    (faster: the range column comes out of the same multiply; the product is then taken in float32); ``out``
    optional (N, 4) float32 (e.g. the shared block).

    With the basis, float32 ranges and C-contiguous arrays, the record is one OpenCV multiply of the basis by
    the range repeated in four channels (``cv2.merge``): the same float32 products as
    :func:`to_points_reference` (OpenCV's multiply at scale 1 is the plain product; tested bit for bit) at
    about a quarter of its instructions (numpy writes the record's strided columns element by element)."""
    n = ranges.shape[0]
    res = np.empty((n, 4), np.float32) if out is None else out
    if (n and directions.shape[1] == 4 and directions.dtype == np.float32 and ranges.dtype == np.float32
            and res.dtype == np.float32 and directions.flags.c_contiguous and ranges.flags.c_contiguous
            and res.flags.c_contiguous and res.shape == (n, 4)):
        r = ranges.reshape(n, 1)
        cv2.multiply(directions.reshape(n, 1, 4), cv2.merge((r, r, r, r)), dst=res.reshape(n, 1, 4))
        return res
    return to_points_reference(directions, ranges, out=res)


def to_points_reference(directions: np.ndarray, ranges: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """:func:`to_points` by numpy alone (the reference of its OpenCV kernel; any dtype and layout)."""
    n = ranges.shape[0]
    res = np.empty((n, 4), np.float32) if out is None else out
    if directions.shape[1] == 4:
        # column by column: one (N,) multiply each (a broadcast (N, 1) operand makes numpy buffer the whole
        # product in chunks of four, about ten times the work); the same float32 products
        for k in range(4):
            np.multiply(directions[:, k], ranges, out=res[:, k], casting="same_kind")
        return res
    np.multiply(directions, ranges[:, None], out=res[:, :3], casting="unsafe")
    res[:, 3] = ranges
    return res
