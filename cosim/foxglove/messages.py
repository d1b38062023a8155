"""A run's blocks as Foxglove messages (foxglove-sdk types), and the JSON schemas of our own channels.

Builders return ``foxglove.messages`` objects, which the SDK encodes in protobuf with Foxglove's schemas; the
recording and the live server send the same (:mod:`cosim.foxglove.publish`). :mod:`cosim.recording.encode`
turns decoded messages back into arrays.

Frames: the LiDAR block (``lidar_points``) is in the sensor frame with the paper's camera axes (X right, Y up,
Z forward), which is left-handed and so cannot be reached from a right-handed frame by a rotation. Points are
therefore sent in the ``lidar`` frame, the sensor *mount* frame with body axes (x forward, y left, z up):
``p_mount = BODY_FROM_CAMERA @ p_cam``, i.e. (x, y, z) = (Z, -X, Y). Height maps ``h[i, j]`` (i along cart
grid x) become a Grid in the ``cart_grid`` frame with columns along x and rows along y (Foxglove's y-major
order), i.e. the bytes of ``h.T``. A depth-encoded image block goes into a RawImage ``rgba8`` byte for byte (R,
G, B carry the depth code, alpha the validity, docs/CONTRACTS.md): lossless. RGB images may be JPEG or PNG
CompressedImage, or RawImage.

Our own channels are JSON: ``cosim.struct.<block>`` (one scalar time series message per struct block and
frame, field descriptions carrying units; Foxglove plots these) and ``cosim.Frame`` (the end-of-frame marker
that makes a killed run's file readable up to its last completed frame). Timestamps are ``{sec, nsec}``.
"""
from __future__ import annotations

import math
from typing import Iterable

import numpy as np
import orjson
from foxglove.messages import (
    CompressedImage,
    FrameTransform,
    Grid,
    PackedElementField,
    PackedElementFieldNumericType,
    PointCloud,
    Pose,
    Quaternion,
    RawImage,
    Timestamp,
    Vector2,
    Vector3,
)

__all__ = ["CLOUD_FIELDS", "CLOUD_STRIDE", "NS_PER_S", "FRAME_MARKER", "stamp", "quaternion_from_matrix",
           "frame_transform", "transform_msg", "planar_transform_msg", "point_cloud_msg", "raw_image_msg", "compressed_image_msg",
           "grid_msg", "scalars_json", "marker_json", "struct_schema", "identity_pose"]

NS_PER_S = 1_000_000_000
#: fields of a recorded point, float32 each: position in the lidar mount frame (m) and range (m)
CLOUD_FIELDS = ("x", "y", "z", "range")
#: bytes per recorded point (CLOUD_FIELDS, float32)
CLOUD_STRIDE = 4 * len(CLOUD_FIELDS)
#: PNG compression level for lossless RGB images (0-9): 1 is fast
PNG_LEVEL = 1
#: column gathers and signs between camera-axes rows (X, Y, Z, r) and mount-frame rows (x, y, z, r)
_MOUNT_FROM_CAM, _MOUNT_SIGN = [2, 0, 1, 3], np.array([1, -1, 1, 1], np.float32)
_F32 = PackedElementFieldNumericType.Float32


def stamp(t_ns: int) -> Timestamp:
    """Foxglove time of a non-negative time in ns."""
    sec, nsec = divmod(max(0, int(t_ns)), NS_PER_S)
    return Timestamp(sec, nsec)


def identity_pose() -> Pose:
    return Pose(position=Vector3(x=0.0, y=0.0, z=0.0), orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0))


def quaternion_from_matrix(r) -> tuple[float, float, float, float]:
    """Unit quaternion (x, y, z, w) of a proper 3 x 3 rotation matrix (or the rotation of a 4 x 4 transform)."""
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(np.asarray(r, dtype=np.float64)[:3, :3]).as_quat().tolist()
    return x, y, z, w


def frame_transform(t_ns: int, parent: str, child: str, xyz, q) -> FrameTransform:
    """FrameTransform of translation ``xyz`` (m) and unit quaternion ``q`` (x, y, z, w)."""
    return FrameTransform(timestamp=stamp(t_ns), parent_frame_id=parent, child_frame_id=child,
                          translation=Vector3(x=xyz[0], y=xyz[1], z=xyz[2]),
                          rotation=Quaternion(x=q[0], y=q[1], z=q[2], w=q[3]))


def transform_msg(t_ns: int, parent: str, child: str, parent_from_child: np.ndarray) -> FrameTransform:
    """FrameTransform from a 4 x 4 rigid transform ``parent_from_child`` (translation in m)."""
    t = np.asarray(parent_from_child, dtype=np.float64)
    return frame_transform(t_ns, parent, child, t[:3, 3].tolist(), quaternion_from_matrix(t))


def planar_transform_msg(t_ns: int, parent: str, child: str, x_m: float, y_m: float, yaw_rad: float) -> FrameTransform:
    """FrameTransform of a pose in the plane: translation (x_m, y_m, 0), rotation yaw_rad about z."""
    return frame_transform(t_ns, parent, child, (float(x_m), float(y_m), 0.0),
                           (0.0, 0.0, math.sin(0.5 * yaw_rad), math.cos(0.5 * yaw_rad)))


def point_cloud_msg(t_ns: int, points_cam: np.ndarray, frame_id: str = "lidar") -> PointCloud:
    """PointCloud of the valid rows of an (N, 4) float32 ``lidar_points`` record (camera axes, m).

    Rows with a non-finite coordinate are invalid beams and are left out. Points are turned from camera axes
    into the mount frame's body axes (module docstring); stride 16 bytes, fields x, y, z, range (FLOAT32).
    """
    p = np.asarray(points_cam, dtype=np.float32).reshape(-1, points_cam.shape[-1])
    if p.shape[1] < 4:
        p = np.column_stack([p[:, :3], np.linalg.norm(p[:, :3], axis=1)])
    out = p[:, _MOUNT_FROM_CAM].astype("<f4", copy=False)
    out *= _MOUNT_SIGN
    if not np.isfinite(out).all():
        out = out[np.isfinite(out[:, :3]).all(axis=1)]
    fields = [PackedElementField(name=n, offset=4 * i, type=_F32) for i, n in enumerate(CLOUD_FIELDS)]
    return PointCloud(timestamp=stamp(t_ns), frame_id=frame_id, pose=identity_pose(), point_stride=CLOUD_STRIDE,
                      fields=fields, data=out.tobytes())


def raw_image_msg(t_ns: int, rgba: np.ndarray, frame_id: str) -> RawImage:
    """RawImage ``rgba8`` of an (H, W, 4) uint8 image block, its bytes unchanged."""
    h, w, c = rgba.shape
    if c != 4 or rgba.dtype != np.uint8:
        raise ValueError(f"rgba8 needs an (H, W, 4) uint8 image, got {rgba.shape} {rgba.dtype}")
    return RawImage(timestamp=stamp(t_ns), frame_id=frame_id, width=w, height=h, encoding="rgba8", step=4 * w,
                    data=np.ascontiguousarray(rgba).tobytes())


def compressed_image_msg(t_ns: int, rgba: np.ndarray, frame_id: str, fmt: str = "jpeg",
                         quality: int = 90) -> CompressedImage:
    """CompressedImage (``png`` or ``jpeg``) of the RGB channels of an (H, W, 4) uint8 image block.

    Never for depth-encoded images: lossy compression decodes to wrong depths, and even PNG drops the alpha
    (validity) channel (docs/CONTRACTS.md); those go through :func:`raw_image_msg`.
    """
    import cv2  # lazily: only RGB camera images need it

    bgr = cv2.cvtColor(rgba, cv2.COLOR_RGBA2BGR) if rgba.shape[-1] == 4 else np.ascontiguousarray(rgba[..., ::-1])
    if fmt == "png":
        ok, buf = cv2.imencode(".png", bgr, [cv2.IMWRITE_PNG_COMPRESSION, PNG_LEVEL])
    elif fmt == "jpeg":
        ok, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, quality])
    else:
        raise ValueError(f"image format {fmt!r} is not 'png' or 'jpeg'")
    if not ok:
        raise ValueError(f"{fmt} encoding failed for an image of shape {bgr.shape}")
    return CompressedImage(timestamp=stamp(t_ns), frame_id=frame_id, format=fmt, data=buf.tobytes())


def grid_msg(t_ns: int, heights: np.ndarray, cell_x_m: float, cell_y_m: float, frame_id: str = "cart_grid") -> Grid:
    """Grid of an (nx, ny) float32 height map (m, NaN unknown) in the cart grid frame (field ``height``)."""
    h = np.asarray(heights, dtype="<f4")
    nx = h.shape[0]
    return Grid(timestamp=stamp(t_ns), frame_id=frame_id, pose=identity_pose(), column_count=nx,
                cell_size=Vector2(x=float(cell_x_m), y=float(cell_y_m)), row_stride=4 * nx, cell_stride=4,
                fields=[PackedElementField(name="height", offset=0, type=_F32)], data=np.ascontiguousarray(h.T).tobytes())


def scalars_json(t_ns: int, frame: int, values: dict) -> bytes:
    """A ``cosim.struct.<block>`` JSON message: ``{timestamp: {sec, nsec}, frame, **values}``; orjson writes
    non-finite floats as ``null`` (JSON has no NaN). orjson, not :func:`json.dumps`: a 60-field dyn_state row
    costs ~10x less (bench/HISTORY.md, 2026-11-25), most of a ground-truth frame's recording cost."""
    sec, nsec = divmod(max(0, int(t_ns)), NS_PER_S)
    return orjson.dumps({"timestamp": {"sec": sec, "nsec": nsec}, "frame": int(frame), **values},
                        option=orjson.OPT_SERIALIZE_NUMPY)


# -- our own JSON channels ----------------------------------------------------------------------------
def _time(desc: str) -> dict:
    return {"type": "object", "title": "time", "description": desc,
            "properties": {"sec": {"type": "integer", "minimum": 0},
                           "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999}}}


def _message(title: str, desc: str, properties: dict) -> dict:
    return {"title": title, "description": desc, "type": "object", "properties": properties}


FRAME_MARKER = _message("cosim.Frame", "End of one completed co-simulation frame (written last in the frame)", {
    "timestamp": _time("Simulation time of the frame"),
    "frame": {"type": "integer", "minimum": 0, "description": "Frame id"},
    "t_s": {"type": "number", "description": "Simulation time, s"},
})


def struct_schema(block: str, fields: Iterable[tuple[str, str]]) -> dict:
    """Schema of the scalar time series of struct block ``block``: ``fields`` are (name, unit) pairs.

    Non-finite values are written as ``null`` (JSON has no NaN).
    """
    props = {"timestamp": _time("Simulation time of the frame"),
             "frame": {"type": "integer", "description": "Frame id"}}
    for name, unit in fields:
        props[name] = {"type": ["number", "null"], "description": f"unit: {unit}" if unit else "dimensionless"}
    return _message(f"cosim.struct.{block}", f"Scalar fields of the shared-memory struct block {block!r}", props)


def marker_json(t_ns: int, frame: int, t_s: float) -> bytes:
    """A ``cosim.Frame`` end-of-frame marker message."""
    sec, nsec = divmod(max(0, int(t_ns)), NS_PER_S)
    return orjson.dumps({"timestamp": {"sec": sec, "nsec": nsec}, "frame": int(frame), "t_s": float(t_s)})
