"""Pure message builders: arrays and transforms to Foxglove JSON messages (dicts), and back.

Builders return dicts whose ``data`` is raw bytes; :func:`to_json` writes them (base64). Decoders take the
JSON-decoded message (``data`` a base64 string).

Frames: the LiDAR block (``lidar_points``) is in the sensor frame with the paper's camera axes (X right, Y up,
Z forward), which is left-handed and so cannot be reached from a right-handed frame by a rotation. The
recording therefore stores points in the ``lidar`` frame, the sensor *mount* frame with body axes (x forward,
y left, z up): ``p_mount = BODY_FROM_CAMERA @ p_cam``, i.e. (x, y, z) = (Z, -X, Y). :func:`points_from_cloud`
undoes it. Height maps ``h[i, j]`` (i along cart grid x) become a Grid in the ``cart_grid`` frame with columns
along x and rows along y (Foxglove's y-major order), i.e. the bytes of ``h.T``.
"""
from __future__ import annotations

import base64
import json
import math

import cv2
import numpy as np

from .schemas import NUMERIC_TYPES

__all__ = [
    "stamp", "quaternion_from_matrix", "transform_msg", "point_cloud_msg", "points_from_cloud", "image_msg",
    "image_from_msg", "grid_msg", "heights_from_grid", "scalars_msg", "CLOUD_FIELDS", "encode_png", "encode_jpeg",
    "to_json",
]

#: fields of a recorded point, float32 each: position in the lidar mount frame (m) and range (m)
CLOUD_FIELDS = ("x", "y", "z", "range")
#: PNG compression level for lossless images (0-9): 1 is fast and still halves the depth-encoded image
PNG_LEVEL = 1


def stamp(t_ns: int) -> dict:
    """Foxglove time ``{sec, nsec}`` of a non-negative time in ns."""
    t_ns = max(0, int(t_ns))
    return {"sec": t_ns // 1_000_000_000, "nsec": t_ns % 1_000_000_000}


def to_json(msg: dict) -> bytes:
    """JSON bytes of a message; a raw ``bytes`` ``data`` field is written as base64 (Foxglove's JSON encoding).

    The base64 text is spliced in rather than passed through ``json.dumps`` (it never needs escaping), which
    keeps a megabyte-sized field cheap. Non-finite floats are refused (JSON has no NaN).
    """
    data = msg.get("data")
    if isinstance(data, (bytes, bytearray, memoryview)):
        head = json.dumps({k: v for k, v in msg.items() if k != "data"}, separators=(",", ":"), allow_nan=False)
        return head[:-1].encode() + b',"data":"' + base64.b64encode(data) + b'"}'
    return json.dumps(msg, separators=(",", ":"), allow_nan=False).encode()


def quaternion_from_matrix(r: np.ndarray) -> dict:
    """Unit quaternion {x, y, z, w} of a proper 3 x 3 rotation matrix (Shepperd's method)."""
    r = np.asarray(r, dtype=np.float64)[:3, :3]
    tr = float(np.trace(r))
    if tr > 0.0:
        s = math.sqrt(tr + 1.0) * 2.0
        q = (0.25 * s, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s)
    elif r[0, 0] > r[1, 1] and r[0, 0] > r[2, 2]:
        s = math.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2]) * 2.0
        q = ((r[2, 1] - r[1, 2]) / s, 0.25 * s, (r[0, 1] + r[1, 0]) / s, (r[0, 2] + r[2, 0]) / s)
    elif r[1, 1] > r[2, 2]:
        s = math.sqrt(1.0 + r[1, 1] - r[0, 0] - r[2, 2]) * 2.0
        q = ((r[0, 2] - r[2, 0]) / s, (r[0, 1] + r[1, 0]) / s, 0.25 * s, (r[1, 2] + r[2, 1]) / s)
    else:
        s = math.sqrt(1.0 + r[2, 2] - r[0, 0] - r[1, 1]) * 2.0
        q = ((r[1, 0] - r[0, 1]) / s, (r[0, 2] + r[2, 0]) / s, (r[1, 2] + r[2, 1]) / s, 0.25 * s)
    w, x, y, z = q
    n = math.sqrt(w * w + x * x + y * y + z * z)
    return {"x": x / n, "y": y / n, "z": z / n, "w": w / n}


def transform_msg(t_ns: int, parent: str, child: str, parent_from_child: np.ndarray) -> dict:
    """foxglove.FrameTransform from a 4 x 4 rigid transform ``parent_from_child``."""
    t = np.asarray(parent_from_child, dtype=np.float64)
    x, y, z = (float(v) for v in t[:3, 3])
    return {"timestamp": stamp(t_ns), "parent_frame_id": parent, "child_frame_id": child,
            "translation": {"x": x, "y": y, "z": z}, "rotation": quaternion_from_matrix(t[:3, :3])}


def point_cloud_msg(t_ns: int, points_cam: np.ndarray, frame_id: str = "lidar") -> dict:
    """foxglove.PointCloud of the valid rows of an (N, 4) float32 ``lidar_points`` record.

    Rows with a non-finite coordinate are invalid beams and are left out. Points are turned from camera axes
    into the mount frame's body axes (module docstring); stride 16 bytes, fields x, y, z, range (FLOAT32).
    """
    p = np.asarray(points_cam, dtype=np.float32).reshape(-1, points_cam.shape[-1])
    ok = np.isfinite(p[:, :3]).all(axis=1)
    p = p[ok]
    out = np.empty((len(p), 4), np.float32)
    out[:, 0] = p[:, 2]
    out[:, 1] = -p[:, 0]
    out[:, 2] = p[:, 1]
    out[:, 3] = p[:, 3] if p.shape[1] > 3 else np.linalg.norm(p[:, :3], axis=1)
    fields = [{"name": n, "offset": 4 * i, "type": NUMERIC_TYPES["f4"]} for i, n in enumerate(CLOUD_FIELDS)]
    return {"timestamp": stamp(t_ns), "frame_id": frame_id,
            "pose": {"position": {"x": 0.0, "y": 0.0, "z": 0.0}, "orientation": {"x": 0.0, "y": 0.0, "z": 0.0,
                                                                                 "w": 1.0}},
            "point_stride": 16, "fields": fields, "data": out.astype("<f4").tobytes()}


def points_from_cloud(msg: dict) -> np.ndarray:
    """(N, 4) float32 rows [X, Y, Z, range] in camera axes (the ``lidar_points`` convention) of a PointCloud."""
    stride = int(msg["point_stride"])
    raw = base64.b64decode(msg["data"])
    if stride != 16 or len(raw) % stride:
        raise ValueError(f"point cloud stride {stride} and {len(raw)} data bytes do not match this recorder's "
                         "layout (16-byte x, y, z, range)")
    m = np.frombuffer(raw, "<f4").reshape(-1, 4)
    out = np.empty_like(m)
    out[:, 0] = -m[:, 1]
    out[:, 1] = m[:, 2]
    out[:, 2] = m[:, 0]
    out[:, 3] = m[:, 3]
    return out


def encode_png(rgb: np.ndarray, level: int = PNG_LEVEL) -> bytes:
    """PNG bytes of an (H, W, 3) RGB uint8 image (lossless)."""
    ok, buf = cv2.imencode(".png", np.ascontiguousarray(rgb[..., ::-1]), [cv2.IMWRITE_PNG_COMPRESSION, level])
    if not ok:
        raise ValueError(f"PNG encoding failed for an image of shape {rgb.shape}")
    return buf.tobytes()


def encode_jpeg(rgb: np.ndarray, quality: int = 90) -> bytes:
    """JPEG bytes of an (H, W, 3) RGB uint8 image."""
    ok, buf = cv2.imencode(".jpg", np.ascontiguousarray(rgb[..., ::-1]), [cv2.IMWRITE_JPEG_QUALITY, quality])
    if not ok:
        raise ValueError(f"JPEG encoding failed for an image of shape {rgb.shape}")
    return buf.tobytes()


def image_msg(t_ns: int, rgba: np.ndarray, frame_id: str, fmt: str = "png", quality: int = 90) -> dict:
    """foxglove.CompressedImage of the RGB channels of an (H, W, 4) uint8 image block.

    Depth-encoded images must use ``png``: lossy compression would decode to wrong depths (DESIGN.md 4).
    """
    rgb = rgba[..., :3] if rgba.shape[-1] == 4 else rgba
    if fmt == "png":
        data = encode_png(rgb)
    elif fmt == "jpeg":
        data = encode_jpeg(rgb, quality)
    else:
        raise ValueError(f"image format {fmt!r} is not 'png' or 'jpeg'")
    return {"timestamp": stamp(t_ns), "frame_id": frame_id, "format": fmt, "data": data}


def image_from_msg(msg: dict) -> np.ndarray:
    """(H, W, 3) RGB uint8 image decoded from a CompressedImage message."""
    buf = np.frombuffer(base64.b64decode(msg["data"]), np.uint8)
    bgr = cv2.imdecode(buf, cv2.IMREAD_COLOR)
    if bgr is None:
        raise ValueError(f"could not decode a {msg.get('format')!r} image of {buf.size} bytes")
    return bgr[..., ::-1].copy()


def grid_msg(t_ns: int, heights: np.ndarray, cell_x_m: float, cell_y_m: float, frame_id: str = "cart_grid") -> dict:
    """foxglove.Grid of an (nx, ny) float32 height map (m, NaN unknown) in the cart grid frame."""
    h = np.asarray(heights, dtype="<f4")
    nx, ny = h.shape
    data = np.ascontiguousarray(h.T).tobytes()
    return {"timestamp": stamp(t_ns), "frame_id": frame_id,
            "pose": {"position": {"x": 0.0, "y": 0.0, "z": 0.0}, "orientation": {"x": 0.0, "y": 0.0, "z": 0.0,
                                                                                 "w": 1.0}},
            "column_count": nx, "cell_size": {"x": float(cell_x_m), "y": float(cell_y_m)},
            "row_stride": 4 * nx, "cell_stride": 4,
            "fields": [{"name": "height", "offset": 0, "type": NUMERIC_TYPES["f4"]}], "data": data}


def heights_from_grid(msg: dict) -> np.ndarray:
    """(nx, ny) float32 height map of a Grid written by :func:`grid_msg`."""
    raw = np.frombuffer(base64.b64decode(msg["data"]), "<f4")
    nx = int(msg["column_count"])
    if nx <= 0 or raw.size % nx:
        raise ValueError(f"grid of {raw.size} cells does not split into rows of {nx} columns")
    return raw.reshape(-1, nx).T.copy()


def scalars_msg(t_ns: int, frame: int, values: dict) -> dict:
    """A ``cosim.struct.<block>`` message: the block's fields, non-finite floats as None (JSON has no NaN)."""
    out: dict = {"timestamp": stamp(t_ns), "frame": int(frame)}
    for k, v in values.items():
        out[k] = v if not isinstance(v, float) or math.isfinite(v) else None
    return out
