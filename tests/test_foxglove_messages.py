"""Foxglove message builders against the protobuf package, and the recording's decoders as their inverses.

Each message is encoded by foxglove-sdk, parsed with the protobuf package from the schema the SDK declares
(``get_schema()``: a FileDescriptorSet) and turned back into arrays by :mod:`cosim.recording.encode`.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cosim.foxglove.messages import (
    compressed_image_msg,
    grid_msg,
    planar_transform_msg,
    point_cloud_msg,
    quaternion_from_matrix,
    raw_image_msg,
    scalars_json,
    transform_msg,
)
from cosim.recording.encode import heights_from_grid, image_from_msg, points_from_cloud
from cosim.recording.reader import _as_dict, _message_class


def parsed(msg) -> dict:
    schema = msg.get_schema()
    assert schema.encoding == "protobuf"
    return _as_dict(_message_class(schema.name, schema.data).FromString(msg.encode()))


@settings(max_examples=25, deadline=None)
@given(st.integers(1, 60), st.integers(0, 2**31), st.floats(0.0, 0.5))
def test_point_cloud_round_trip_keeps_valid_beams(n, seed, invalid):
    rng = np.random.default_rng(seed)
    pts = rng.normal(0, 5, (n, 4)).astype(np.float32)
    pts[rng.random(n) < invalid] = np.nan
    m = parsed(point_cloud_msg(123_456_789, pts))
    assert (m["frame_id"], m["point_stride"], [f["name"] for f in m["fields"]]) == ("lidar", 16, ["x", "y", "z", "range"])
    assert m["timestamp"] == {"sec": 0, "nsec": 123_456_789}
    np.testing.assert_array_equal(points_from_cloud(m), pts[np.isfinite(pts[:, 0])])
    mount = np.frombuffer(m["data"], "<f4").reshape(-1, 4)
    valid = pts[np.isfinite(pts[:, 0])]
    # the lidar (mount) frame has body axes: x = Z, y = -X, z = Y of the camera-axes block
    np.testing.assert_array_equal(mount[:, :3], np.column_stack([valid[:, 2], -valid[:, 0], valid[:, 1]]))


def test_grid_and_images_round_trip():
    h = np.arange(12, dtype=np.float32).reshape(4, 3)
    h[1, 2] = np.nan
    g = parsed(grid_msg(5 * 10**9, h, 0.5, 0.25))
    assert (g["column_count"], g["row_stride"], g["cell_stride"], g["cell_size"]) == (4, 16, 4, {"x": 0.5, "y": 0.25})
    np.testing.assert_array_equal(heights_from_grid(g), h)
    rgba = np.random.default_rng(1).integers(0, 256, (6, 5, 4), dtype=np.uint8)
    raw = parsed(raw_image_msg(0, rgba, "cam0"))
    assert (raw["encoding"], raw["width"], raw["height"], raw["step"], raw["frame_id"]) == ("rgba8", 5, 6, 20, "cam0")
    np.testing.assert_array_equal(image_from_msg(raw), rgba)
    png = parsed(compressed_image_msg(0, rgba, "cam0", "png"))
    assert png["format"] == "png"
    np.testing.assert_array_equal(image_from_msg(png), rgba[..., :3], "PNG keeps the RGB channels exactly")
    with pytest.raises(ValueError, match="rgba8 needs an"):
        raw_image_msg(0, rgba[..., :3], "cam0")


@settings(max_examples=40, deadline=None)
@given(st.floats(-math.pi, math.pi), st.floats(-1.5, 1.5), st.floats(-math.pi, math.pi))
def test_transform_quaternion_rotates_like_the_matrix(yaw, pitch, roll):
    from scipy.spatial.transform import Rotation

    r = Rotation.from_euler("zyx", [yaw, pitch, roll]).as_matrix()
    tf = np.eye(4)
    tf[:3, :3], tf[:3, 3] = r, [1.0, -2.0, 3.5]
    m = parsed(transform_msg(10, "cart", "lidar", tf))
    q = m["rotation"]
    x, y, z, w = q["x"], q["y"], q["z"], q["w"]
    from_q = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                       [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                       [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    np.testing.assert_allclose(from_q, r, atol=1e-12)
    assert (m["parent_frame_id"], m["child_frame_id"], m["translation"]) == ("cart", "lidar",
                                                                           {"x": 1.0, "y": -2.0, "z": 3.5})
    assert np.allclose(quaternion_from_matrix(tf), (x, y, z, w))


def test_planar_transform_is_a_yaw_about_z():
    m = parsed(planar_transform_msg(0, "world", "cart", 2.0, -1.0, 0.3))
    assert m["rotation"] == pytest.approx({"x": 0.0, "y": 0.0, "z": math.sin(0.15), "w": math.cos(0.15)})
    assert m["translation"] == {"x": 2.0, "y": -1.0, "z": 0.0}


def test_scalars_json_writes_non_finite_as_null():
    import json

    out = json.loads(scalars_json(1_500_000_000, 15, {"a": 1.5, "b": float("nan"), "c": float("-inf"), "n": 3}))
    assert out == {"timestamp": {"sec": 1, "nsec": 500_000_000}, "frame": 15, "a": 1.5, "b": None, "c": None, "n": 3}


def test_scalars_json_takes_numpy_scalars():
    import json

    out = json.loads(scalars_json(0, 1, {"a": np.float64(0.1), "b": np.int64(7), "c": np.float32("nan")}))
    assert (out["a"], out["b"], out["c"]) == (0.1, 7, None)
