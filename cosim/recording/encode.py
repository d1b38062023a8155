"""Decoded Foxglove messages (dicts from :func:`cosim.recording.reader.read_recording`) back into arrays.

The inverses of :mod:`cosim.foxglove.messages`' builders: a PointCloud's ``lidar`` (mount) frame points back to
the ``lidar_points`` block's camera axes ((X, Y, Z) = (-y, z, x)), a Grid's y-major cells back to (nx, ny),
and a RawImage or CompressedImage back to its pixels.
"""
from __future__ import annotations

import numpy as np

from cosim.foxglove.messages import CLOUD_STRIDE

__all__ = ["points_from_cloud", "image_from_msg", "heights_from_grid"]

#: column gathers and signs from mount-frame rows (x, y, z, r) to camera-axes rows (X, Y, Z, r)
_CAM_FROM_MOUNT, _CAM_SIGN = [1, 2, 0, 3], np.array([-1, 1, 1, 1], np.float32)


def points_from_cloud(msg: dict) -> np.ndarray:
    """(N, 4) float32 rows [X, Y, Z, range] in camera axes (the ``lidar_points`` convention) of a PointCloud."""
    stride = int(msg["point_stride"])
    raw = msg["data"]
    if stride != CLOUD_STRIDE or len(raw) % stride:
        raise ValueError(f"point cloud stride {stride} and {len(raw)} data bytes do not match this recorder's "
                         "layout (16-byte x, y, z, range)")
    m = np.frombuffer(raw, "<f4").reshape(-1, 4)
    return (m[:, _CAM_FROM_MOUNT] * _CAM_SIGN).astype(np.float32, copy=False)


def image_from_msg(msg: dict) -> np.ndarray:
    """The image of a RawImage (``rgba8`` -> (H, W, 4), ``rgb8`` -> (H, W, 3), ``mono8`` -> (H, W) uint8,
    ``32FC1`` -> (H, W) float32) or CompressedImage ((H, W, 3) RGB) message dict, uint8 unless said."""
    import cv2

    if "encoding" in msg:
        if msg["encoding"] in ("mono8", "32FC1"):
            dtype = np.dtype(np.uint8) if msg["encoding"] == "mono8" else np.dtype("<f4")
            h, w, step = int(msg["height"]), int(msg["width"]), int(msg["step"])
            raw = np.frombuffer(msg["data"], np.uint8)
            if step < dtype.itemsize * w or raw.size < step * h:
                raise ValueError(f"raw image {w} x {h} step {step} does not fit its {raw.size} data bytes")
            rows = raw[:step * h].reshape(h, step)[:, :dtype.itemsize * w]
            return np.ascontiguousarray(rows).view(dtype).reshape(h, w).copy()
        channels = {"rgba8": 4, "rgb8": 3}.get(msg["encoding"])
        if channels is None:
            raise ValueError(f"raw image encoding {msg['encoding']!r} is not rgba8, rgb8, mono8 or 32FC1")
        h, w, step = int(msg["height"]), int(msg["width"]), int(msg["step"])
        raw = np.frombuffer(msg["data"], np.uint8)
        if step < channels * w or raw.size < step * h:
            raise ValueError(f"raw image {w} x {h} step {step} does not fit its {raw.size} data bytes")
        return raw[:step * h].reshape(h, step)[:, :channels * w].reshape(h, w, channels).copy()
    buf = np.frombuffer(msg["data"], np.uint8)
    bgr = cv2.imdecode(buf, cv2.IMREAD_COLOR)
    if bgr is None:
        raise ValueError(f"could not decode a {msg.get('format')!r} image of {buf.size} bytes")
    return bgr[..., ::-1].copy()


def heights_from_grid(msg: dict) -> np.ndarray:
    """(nx, ny) float32 height map of a Grid written by :func:`grid_msg`."""
    raw = np.frombuffer(msg["data"], "<f4")
    nx = int(msg["column_count"])
    if nx <= 0 or raw.size % nx:
        raise ValueError(f"grid of {raw.size} cells does not split into rows of {nx} columns")
    return raw.reshape(-1, nx).T.copy()
