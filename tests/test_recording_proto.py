"""The hand-written protobuf wire format of Foxglove's schemas, checked against the protobuf package.

The protobuf package is the independent decoder and encoder here; the expected descriptors are transcribed
separately from foxglove/schemas ``schemas/proto/foxglove/*.proto`` (not derived from cosim.recording.proto).
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from hypothesis import given, settings
from hypothesis import strategies as st

from cosim.recording import proto
from cosim.recording.encode import (
    grid_msg,
    heights_from_grid,
    image_from_msg,
    planar_transform_msg,
    point_cloud_msg,
    points_from_cloud,
    raw_image_msg,
    transform_msg,
)

# field -> (number, FieldDescriptorProto type name, repeated, type name) as in Foxglove's .proto files
FOXGLOVE = {
    "foxglove.PointCloud": {"timestamp": (1, "MESSAGE", False, ".google.protobuf.Timestamp"),
                            "frame_id": (2, "STRING", False, ""), "pose": (3, "MESSAGE", False, ".foxglove.Pose"),
                            "point_stride": (4, "FIXED32", False, ""),
                            "fields": (5, "MESSAGE", True, ".foxglove.PackedElementField"),
                            "data": (6, "BYTES", False, "")},
    "foxglove.RawImage": {"timestamp": (1, "MESSAGE", False, ".google.protobuf.Timestamp"),
                          "frame_id": (7, "STRING", False, ""), "width": (2, "FIXED32", False, ""),
                          "height": (3, "FIXED32", False, ""), "encoding": (4, "STRING", False, ""),
                          "step": (5, "FIXED32", False, ""), "data": (6, "BYTES", False, "")},
    "foxglove.CompressedImage": {"timestamp": (1, "MESSAGE", False, ".google.protobuf.Timestamp"),
                                 "frame_id": (4, "STRING", False, ""), "data": (2, "BYTES", False, ""),
                                 "format": (3, "STRING", False, "")},
    "foxglove.Grid": {"timestamp": (1, "MESSAGE", False, ".google.protobuf.Timestamp"),
                      "frame_id": (2, "STRING", False, ""), "pose": (3, "MESSAGE", False, ".foxglove.Pose"),
                      "column_count": (4, "FIXED32", False, ""), "cell_size": (5, "MESSAGE", False, ".foxglove.Vector2"),
                      "row_stride": (6, "FIXED32", False, ""), "cell_stride": (7, "FIXED32", False, ""),
                      "fields": (8, "MESSAGE", True, ".foxglove.PackedElementField"), "data": (9, "BYTES", False, "")},
    "foxglove.FrameTransform": {"timestamp": (1, "MESSAGE", False, ".google.protobuf.Timestamp"),
                                "parent_frame_id": (2, "STRING", False, ""), "child_frame_id": (3, "STRING", False, ""),
                                "translation": (4, "MESSAGE", False, ".foxglove.Vector3"),
                                "rotation": (5, "MESSAGE", False, ".foxglove.Quaternion")},
    "foxglove.PackedElementField": {"name": (1, "STRING", False, ""), "offset": (2, "FIXED32", False, ""),
                                    "type": (3, "ENUM", False, ".foxglove.PackedElementField.NumericType")},
    "foxglove.Pose": {"position": (1, "MESSAGE", False, ".foxglove.Vector3"),
                      "orientation": (2, "MESSAGE", False, ".foxglove.Quaternion")},
    "foxglove.Vector2": {"x": (1, "DOUBLE", False, ""), "y": (2, "DOUBLE", False, "")},
    "foxglove.Vector3": {k: (i + 1, "DOUBLE", False, "") for i, k in enumerate("xyz")},
    "foxglove.Quaternion": {k: (i + 1, "DOUBLE", False, "") for i, k in enumerate("xyzw")},
    "google.protobuf.Timestamp": {"seconds": (1, "INT64", False, ""), "nanos": (2, "INT32", False, "")},
}
NUMERIC_TYPE = ["UNKNOWN", "UINT8", "INT8", "UINT16", "INT16", "UINT32", "INT32", "FLOAT32", "FLOAT64"]
TOP = ["foxglove.PointCloud", "foxglove.RawImage", "foxglove.CompressedImage", "foxglove.Grid",
       "foxglove.FrameTransform"]


def message_class(name: str):
    """The protobuf package's message class for ``name``, built from our descriptor set alone."""
    fds = descriptor_pb2.FileDescriptorSet.FromString(proto.descriptor_set(name))
    pool = descriptor_pool.DescriptorPool()
    for f in fds.file:
        pool.Add(f)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(name))


@pytest.mark.parametrize("name", TOP)
def test_descriptor_sets_match_foxglove_proto_files(name):
    fds = descriptor_pb2.FileDescriptorSet.FromString(proto.descriptor_set(name))
    files = {f.name: f for f in fds.file}
    assert f"foxglove/{name.split('.')[1]}.proto" in files and "google/protobuf/timestamp.proto" in files
    seen = {}
    for f in fds.file:
        assert f.syntax == "proto3"
        assert set(f.dependency) <= set(files), f"{f.name} depends on a file the set lacks"
        for m in f.message_type:
            full = f"{f.package}.{m.name}"
            seen[full] = {fd.name: (fd.number, descriptor_pb2.FieldDescriptorProto.Type.Name(fd.type)[5:],
                                    fd.label == fd.LABEL_REPEATED, fd.type_name) for fd in m.field}
            if m.enum_type:
                assert [(v.name, v.number) for v in m.enum_type[0].value] == list(zip(NUMERIC_TYPE, range(9)))
    assert seen[name] == FOXGLOVE[name]
    for full, fields in seen.items():
        assert fields == FOXGLOVE[full], full


def _sample(name: str) -> dict:
    ts = {"sec": 12, "nsec": 345_000_000}
    if name == "foxglove.PointCloud":
        pts = np.array([[1.0, np.nan, 0, 0], [4.0, -2.5, 3.0, 5.0], [0.5, 0.25, 8.0, 9.0]], np.float32)
        return point_cloud_msg(12_345_000_000, pts)
    if name == "foxglove.RawImage":
        img = np.arange(3 * 5 * 4, dtype=np.uint8).reshape(3, 5, 4)
        return raw_image_msg(12_345_000_000, img, "cam1")
    if name == "foxglove.CompressedImage":
        return {"timestamp": ts, "frame_id": "cam0", "data": b"\xff\xd8 not really a jpeg", "format": "jpeg"}
    if name == "foxglove.Grid":
        h = np.arange(6, dtype=np.float32).reshape(3, 2)
        h[1, 1] = np.nan
        return grid_msg(12_345_000_000, h, 0.25, 0.5)
    return transform_msg(12_345_000_000, "world", "cart", np.array([[0, -1, 0, 1.5], [1, 0, 0, -2], [0, 0, 1, 0.25],
                                                                     [0, 0, 0, 1]], float))


def _repeated(fd) -> bool:
    return fd.is_repeated if hasattr(fd, "is_repeated") else fd.label == fd.LABEL_REPEATED


def _as_plain(msg) -> dict:
    """A parsed protobuf message as the dict our decoder returns (timestamps as {sec, nsec}, bytes as bytes)."""
    out = {}
    for fd in msg.DESCRIPTOR.fields:
        v = getattr(msg, fd.name)
        if fd.message_type is not None and fd.message_type.full_name == "google.protobuf.Timestamp":
            out[fd.name] = {"sec": v.seconds, "nsec": v.nanos}
        elif _repeated(fd):
            out[fd.name] = [_as_plain(x) for x in v]
        elif fd.message_type is not None:
            out[fd.name] = _as_plain(v)
        else:
            out[fd.name] = v
    return out


@pytest.mark.parametrize("name", TOP)
def test_our_bytes_parse_with_protobuf_and_back(name):
    msg = _sample(name)
    data = proto.encode(name, msg)
    theirs = message_class(name).FromString(data)
    ours = proto.decode(name, data)
    assert _as_plain(theirs) == ours
    # and the other way: the protobuf package's canonical bytes (defaults left out) decode to the same
    assert proto.decode(name, theirs.SerializeToString()) == ours
    assert ours["timestamp"] == {"sec": 12, "nsec": 345_000_000}
    if "data" in msg:
        assert ours["data"] == bytes(memoryview(np.ascontiguousarray(msg["data"])).cast("B")
                                     if isinstance(msg["data"], np.ndarray) else msg["data"])


def test_decoded_payloads_give_back_the_arrays():
    cloud = proto.decode("foxglove.PointCloud", proto.encode("foxglove.PointCloud", _sample("foxglove.PointCloud")))
    np.testing.assert_array_equal(points_from_cloud(cloud),
                                  np.array([[4.0, -2.5, 3.0, 5.0], [0.5, 0.25, 8.0, 9.0]], np.float32))
    assert [f["name"] for f in cloud["fields"]] == ["x", "y", "z", "range"] and cloud["point_stride"] == 16
    img = proto.decode("foxglove.RawImage", proto.encode("foxglove.RawImage", _sample("foxglove.RawImage")))
    assert (img["width"], img["height"], img["step"], img["encoding"]) == (5, 3, 20, "rgba8")
    np.testing.assert_array_equal(image_from_msg(img), np.arange(60, dtype=np.uint8).reshape(3, 5, 4))
    grid = proto.decode("foxglove.Grid", proto.encode("foxglove.Grid", _sample("foxglove.Grid")))
    h = np.arange(6, dtype=np.float32).reshape(3, 2)
    h[1, 1] = np.nan
    np.testing.assert_array_equal(heights_from_grid(grid), h)
    assert grid["cell_size"] == {"x": 0.25, "y": 0.5} and grid["row_stride"] == 12


@settings(max_examples=60, deadline=None)
@given(st.floats(-1e6, 1e6), st.floats(-1e6, 1e6), st.floats(-math.pi, math.pi),
       st.integers(0, 2**40), st.text(max_size=12))
def test_transforms_round_trip_through_protobuf(x, y, yaw, t_ns, child):
    msg = planar_transform_msg(t_ns, "world", child, x, y, yaw)
    theirs = message_class("foxglove.FrameTransform").FromString(proto.encode("foxglove.FrameTransform", msg))
    assert theirs.child_frame_id == child and theirs.translation.x == x and theirs.translation.y == y
    assert theirs.timestamp.seconds * 1_000_000_000 + theirs.timestamp.nanos == t_ns
    assert theirs.rotation.z == pytest.approx(math.sin(yaw / 2)) and theirs.rotation.w == pytest.approx(math.cos(yaw / 2))
    assert proto.decode("foxglove.FrameTransform", theirs.SerializeToString())["child_frame_id"] == child


def test_unknown_fields_are_skipped_and_damage_is_refused():
    cls = message_class("foxglove.CompressedImage")
    data = cls(frame_id="cam0", format="png", data=b"abc").SerializeToString()
    extra = bytes([0xA2, 0x06, 3]) + b"xyz"  # field 100, length-delimited (message_id in newer schemas): skipped
    assert proto.decode("foxglove.CompressedImage", data + extra)["data"] == b"abc"
    with pytest.raises(proto.ProtoError, match="runs past the end"):
        proto.decode("foxglove.CompressedImage", data[:-1])
    with pytest.raises(proto.ProtoError, match="unsupported wire type"):
        proto.decode("foxglove.CompressedImage", bytes([1 << 3 | 3]))


def test_scalars_json_is_scalars_msg_as_json():
    import json

    from cosim.recording.encode import scalars_json, scalars_msg, to_json

    values = {"t_s": 0.1, "spilled_m3": float("nan"), "a_inf": float("inf"), "b": -float("inf"), "n": 3,
              "NaN_count": 2.5, "x_m": -1e-300}
    fast = scalars_json(1_500_000_000, 15, values)
    assert fast == to_json(scalars_msg(1_500_000_000, 15, values))
    assert json.loads(fast)["spilled_m3"] is None and json.loads(fast)["NaN_count"] == 2.5
