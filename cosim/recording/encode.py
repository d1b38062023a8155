"""Pure message builders: arrays and transforms to Foxglove messages (dicts), and back.

Builders return the dicts that :func:`cosim.recording.proto.encode` writes: ``data`` is a buffer (a numpy array
or bytes, written as is), timestamps are ``{sec, nsec}``. Decoders take the dicts that
:func:`cosim.recording.proto.decode` returns (``data`` bytes). Our own ``cosim.*`` messages are JSON
(:func:`to_json`).

Frames: the LiDAR block (``lidar_points``) is in the sensor frame with the paper's camera axes (X right, Y up,
Z forward), which is left-handed and so cannot be reached from a right-handed frame by a rotation. The
recording therefore stores points in the ``lidar`` frame, the sensor *mount* frame with body axes (x forward,
y left, z up): ``p_mount = BODY_FROM_CAMERA @ p_cam``, i.e. (x, y, z) = (Z, -X, Y). :func:`points_from_cloud`
undoes it. Height maps ``h[i, j]`` (i along cart grid x) become a Grid in the ``cart_grid`` frame with columns
along x and rows along y (Foxglove's y-major order), i.e. the bytes of ``h.T``.

Images: a depth-encoded image block goes into a foxglove.RawImage ``rgba8`` byte for byte (R, G, B carry the
depth code, alpha the validity, DESIGN.md 4): lossless and no encoding work, the chunk compression (lz4) then
shrinks it ~18 x. RGB camera images may be JPEG or PNG foxglove.CompressedImage, or RawImage as well.
"""
from __future__ import annotations

import json
import math
import re

import numpy as np

__all__ = [
    "NUMERIC_TYPES", "CLOUD_FIELDS", "PNG_LEVEL", "stamp", "quaternion_from_matrix", "transform_msg",
    "planar_transform_msg", "point_cloud_msg", "points_from_cloud", "raw_image_msg", "compressed_image_msg", "image_from_msg",
    "grid_msg", "heights_from_grid", "scalars_msg", "scalars_json", "encode_png", "encode_jpeg", "to_json",
]

#: foxglove.PackedElementField.NumericType values by numpy dtype string
NUMERIC_TYPES = {"u1": 1, "i1": 2, "u2": 3, "i2": 4, "u4": 5, "i4": 6, "f4": 7, "f8": 8}
#: fields of a recorded point, float32 each: position in the lidar mount frame (m) and range (m)
CLOUD_FIELDS = ("x", "y", "z", "range")
#: bytes per recorded point (CLOUD_FIELDS, float32)
CLOUD_STRIDE = 4 * len(CLOUD_FIELDS)
#: PNG compression level for lossless RGB images (0-9): 1 is fast
PNG_LEVEL = 1
#: column gathers and signs between camera-axes rows (X, Y, Z, r) and mount-frame rows (x, y, z, r)
_MOUNT_FROM_CAM, _MOUNT_SIGN = [2, 0, 1, 3], np.array([1, -1, 1, 1], np.float32)
_CAM_FROM_MOUNT, _CAM_SIGN = [1, 2, 0, 3], np.array([-1, 1, 1, 1], np.float32)
_IDENTITY_POSE = {"position": {"x": 0.0, "y": 0.0, "z": 0.0}, "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}}
_CLOUD_FIELDS = [{"name": n, "offset": 4 * i, "type": NUMERIC_TYPES["f4"]} for i, n in enumerate(CLOUD_FIELDS)]


def stamp(t_ns: int) -> dict:
    """Foxglove time ``{sec, nsec}`` of a non-negative time in ns."""
    t_ns = max(0, int(t_ns))
    return {"sec": t_ns // 1_000_000_000, "nsec": t_ns % 1_000_000_000}


def to_json(msg: dict) -> bytes:
    """Compact JSON bytes of a message; non-finite floats are refused (JSON has no NaN)."""
    return json.dumps(msg, separators=(",", ":"), allow_nan=False).encode()


def quaternion_from_matrix(r) -> dict:
    """Unit quaternion {x, y, z, w} of a proper 3 x 3 rotation matrix (Shepperd's method)."""
    r = np.asarray(r, dtype=np.float64)[:3, :3].tolist()
    tr = r[0][0] + r[1][1] + r[2][2]
    if tr > 0.0:
        s = math.sqrt(tr + 1.0) * 2.0
        q = (0.25 * s, (r[2][1] - r[1][2]) / s, (r[0][2] - r[2][0]) / s, (r[1][0] - r[0][1]) / s)
    elif r[0][0] > r[1][1] and r[0][0] > r[2][2]:
        s = math.sqrt(1.0 + r[0][0] - r[1][1] - r[2][2]) * 2.0
        q = ((r[2][1] - r[1][2]) / s, 0.25 * s, (r[0][1] + r[1][0]) / s, (r[0][2] + r[2][0]) / s)
    elif r[1][1] > r[2][2]:
        s = math.sqrt(1.0 + r[1][1] - r[0][0] - r[2][2]) * 2.0
        q = ((r[0][2] - r[2][0]) / s, (r[0][1] + r[1][0]) / s, 0.25 * s, (r[1][2] + r[2][1]) / s)
    else:
        s = math.sqrt(1.0 + r[2][2] - r[0][0] - r[1][1]) * 2.0
        q = ((r[1][0] - r[0][1]) / s, (r[0][2] + r[2][0]) / s, (r[1][2] + r[2][1]) / s, 0.25 * s)
    w, x, y, z = q
    n = math.sqrt(w * w + x * x + y * y + z * z)
    return {"x": x / n, "y": y / n, "z": z / n, "w": w / n}


def transform_msg(t_ns: int, parent: str, child: str, parent_from_child: np.ndarray) -> dict:
    """foxglove.FrameTransform from a 4 x 4 rigid transform ``parent_from_child`` (translation in m)."""
    t = np.asarray(parent_from_child, dtype=np.float64)
    x, y, z = t[:3, 3].tolist()
    return {"timestamp": stamp(t_ns), "parent_frame_id": parent, "child_frame_id": child,
            "translation": {"x": x, "y": y, "z": z}, "rotation": quaternion_from_matrix(t[:3, :3])}


def planar_transform_msg(t_ns: int, parent: str, child: str, x_m: float, y_m: float, yaw_rad: float) -> dict:
    """foxglove.FrameTransform of a pose in the plane: translation (x_m, y_m, 0), rotation yaw_rad about z."""
    return {"timestamp": stamp(t_ns), "parent_frame_id": parent, "child_frame_id": child,
            "translation": {"x": float(x_m), "y": float(y_m), "z": 0.0},
            "rotation": {"x": 0.0, "y": 0.0, "z": math.sin(0.5 * yaw_rad), "w": math.cos(0.5 * yaw_rad)}}


def point_cloud_msg(t_ns: int, points_cam: np.ndarray, frame_id: str = "lidar", out: np.ndarray | None = None) -> dict:
    """foxglove.PointCloud of the valid rows of an (N, 4) float32 ``lidar_points`` record (camera axes, m).

    Rows with a non-finite coordinate are invalid beams and are left out. Points are turned from camera axes
    into the mount frame's body axes (module docstring); stride 16 bytes, fields x, y, z, range (FLOAT32).
    ``out``: an (M >= N, 4) float32 C-contiguous buffer the points are written into (the message's ``data`` is
    then a view of it, valid until it is reused), so that a recorder reuses one buffer for every frame.
    """
    p = np.asarray(points_cam, dtype=np.float32).reshape(-1, points_cam.shape[-1])
    if p.shape[1] < 4:
        p = np.column_stack([p[:, :3], np.linalg.norm(p[:, :3], axis=1)])
    # (x, y, z, range) = (Z, -X, Y, range): gather then scale in place (a ufunc with a strided out= is avoided:
    # numpy 2.4.6 computes np.negative(strided, out=strided) wrongly on this machine); filter after, and only
    # when some beam is invalid (one cheap pass over every value tells)
    if out is None:
        out = p[:, _MOUNT_FROM_CAM].astype("<f4", copy=False)
    else:
        if out.dtype != np.dtype("<f4") or out.ndim != 2 or out.shape[1] != 4 or len(out) < len(p) \
                or not out.flags.c_contiguous:
            raise ValueError(f"out must be an (M >= {len(p)}, 4) C-contiguous float32 array, "
                             f"got {out.shape} {out.dtype}")
        out = out[:len(p)]
        np.take(p, _MOUNT_FROM_CAM, axis=1, out=out, mode="clip")
    out *= _MOUNT_SIGN
    if not np.isfinite(out).all():
        ok = np.isfinite(out[:, :3]).all(axis=1)
        out = out[ok]
    return {"timestamp": stamp(t_ns), "frame_id": frame_id, "pose": _IDENTITY_POSE, "point_stride": CLOUD_STRIDE,
            "fields": _CLOUD_FIELDS, "data": out}


def points_from_cloud(msg: dict) -> np.ndarray:
    """(N, 4) float32 rows [X, Y, Z, range] in camera axes (the ``lidar_points`` convention) of a PointCloud."""
    stride = int(msg["point_stride"])
    raw = msg["data"]
    if stride != CLOUD_STRIDE or len(raw) % stride:
        raise ValueError(f"point cloud stride {stride} and {len(raw)} data bytes do not match this recorder's "
                         "layout (16-byte x, y, z, range)")
    m = np.frombuffer(raw, "<f4").reshape(-1, 4)
    return (m[:, _CAM_FROM_MOUNT] * _CAM_SIGN).astype(np.float32, copy=False)


def raw_image_msg(t_ns: int, rgba: np.ndarray, frame_id: str) -> dict:
    """foxglove.RawImage ``rgba8`` of an (H, W, 4) uint8 image block, its bytes unchanged (no copy)."""
    h, w, c = rgba.shape
    if c != 4 or rgba.dtype != np.uint8:
        raise ValueError(f"rgba8 needs an (H, W, 4) uint8 image, got {rgba.shape} {rgba.dtype}")
    return {"timestamp": stamp(t_ns), "frame_id": frame_id, "width": w, "height": h, "encoding": "rgba8",
            "step": 4 * w, "data": np.ascontiguousarray(rgba)}


def encode_png(bgr: np.ndarray, level: int = PNG_LEVEL) -> bytes:
    """PNG bytes of an (H, W, 3) BGR uint8 image (lossless)."""
    import cv2  # lazily: the recorder process needs it only for RGB camera images

    ok, buf = cv2.imencode(".png", bgr, [cv2.IMWRITE_PNG_COMPRESSION, level])
    if not ok:
        raise ValueError(f"PNG encoding failed for an image of shape {bgr.shape}")
    return buf.tobytes()


def encode_jpeg(bgr: np.ndarray, quality: int = 90) -> bytes:
    """JPEG bytes of an (H, W, 3) BGR uint8 image."""
    import cv2  # lazily: the recorder process needs it only for RGB camera images

    ok, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, quality])
    if not ok:
        raise ValueError(f"JPEG encoding failed for an image of shape {bgr.shape}")
    return buf.tobytes()


def compressed_image_msg(t_ns: int, rgba: np.ndarray, frame_id: str, fmt: str = "jpeg", quality: int = 90) -> dict:
    """foxglove.CompressedImage (``png`` or ``jpeg``) of the RGB channels of an (H, W, 4) uint8 image block.

    Never for depth-encoded images: lossy compression decodes to wrong depths, and even PNG drops the alpha
    (validity) channel (DESIGN.md 4); those go through :func:`raw_image_msg`.
    """
    import cv2  # lazily: the recorder process needs it only for RGB camera images

    bgr = cv2.cvtColor(rgba, cv2.COLOR_RGBA2BGR) if rgba.shape[-1] == 4 else np.ascontiguousarray(rgba[..., ::-1])
    if fmt == "png":
        data = encode_png(bgr)
    elif fmt == "jpeg":
        data = encode_jpeg(bgr, quality)
    else:
        raise ValueError(f"image format {fmt!r} is not 'png' or 'jpeg'")
    return {"timestamp": stamp(t_ns), "frame_id": frame_id, "format": fmt, "data": data}


def image_from_msg(msg: dict) -> np.ndarray:
    """The image of a RawImage (``rgba8`` -> (H, W, 4), ``rgb8`` -> (H, W, 3)) or CompressedImage ((H, W, 3) RGB)
    message, uint8."""
    import cv2  # lazily: the recorder process needs it only for RGB camera images

    if "encoding" in msg:
        channels = {"rgba8": 4, "rgb8": 3}.get(msg["encoding"])
        if channels is None:
            raise ValueError(f"raw image encoding {msg['encoding']!r} is not rgba8 or rgb8")
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


def grid_msg(t_ns: int, heights: np.ndarray, cell_x_m: float, cell_y_m: float, frame_id: str = "cart_grid") -> dict:
    """foxglove.Grid of an (nx, ny) float32 height map (m, NaN unknown) in the cart grid frame."""
    h = np.asarray(heights, dtype="<f4")
    nx = h.shape[0]
    return {"timestamp": stamp(t_ns), "frame_id": frame_id, "pose": _IDENTITY_POSE, "column_count": nx,
            "cell_size": {"x": float(cell_x_m), "y": float(cell_y_m)}, "row_stride": 4 * nx, "cell_stride": 4,
            "fields": [{"name": "height", "offset": 0, "type": NUMERIC_TYPES["f4"]}],
            "data": np.ascontiguousarray(h.T)}


def heights_from_grid(msg: dict) -> np.ndarray:
    """(nx, ny) float32 height map of a Grid written by :func:`grid_msg`."""
    raw = np.frombuffer(msg["data"], "<f4")
    nx = int(msg["column_count"])
    if nx <= 0 or raw.size % nx:
        raise ValueError(f"grid of {raw.size} cells does not split into rows of {nx} columns")
    return raw.reshape(-1, nx).T.copy()


#: a non-finite float where JSON has a value (after ``:`` or ``,`` or ``[``, before ``,`` ``}`` or ``]``)
_NON_FINITE = re.compile(rb"(?<=[:,\[])(?:-?Infinity|NaN)(?=[,}\]])")


def scalars_json(t_ns: int, frame: int, values: dict) -> bytes:
    """``to_json(scalars_msg(t_ns, frame, values))``, faster: numbers serialized by the C encoder, non-finite
    ones then turned into ``null`` (``values`` keys are struct field names, identifiers, so no key can hold a
    NaN token)."""
    out = json.dumps({"timestamp": stamp(t_ns), "frame": int(frame), **values}, separators=(",", ":"),
                     allow_nan=True).encode()
    if b"NaN" in out or b"Infinity" in out:
        out = _NON_FINITE.sub(b"null", out)
    return out


def scalars_msg(t_ns: int, frame: int, values: dict) -> dict:
    """A ``cosim.struct.<block>`` message: the block's fields, non-finite floats as None (JSON has no NaN)."""
    out: dict = {"timestamp": stamp(t_ns), "frame": int(frame)}
    for k, v in values.items():
        out[k] = v if not isinstance(v, float) or math.isfinite(v) else None
    return out
