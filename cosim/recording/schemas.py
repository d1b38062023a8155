"""Foxglove's well-known message schemas as JSON-schema dicts (JSON message encoding), plus this project's own.

The definitions follow foxglove/schemas (``schemas/jsonschema/*.json``): timestamps are ``{sec, nsec}``, byte
fields are base64 strings (``contentEncoding: base64``), packed element fields carry a ``foxglove.NumericType``.
Foxglove, Lichtblick and Rerun recognise a channel by the schema *name* (``foxglove.PointCloud`` ...), so those
names are fixed here; the bodies let the tools validate and show field descriptions.

Our own schemas: ``cosim.struct.<block>`` (one scalar time series message per struct block and frame, field
names carrying units) and ``cosim.Frame`` (the end-of-frame marker that makes a killed run's file readable up to
its last completed frame).
"""
from __future__ import annotations

import json
from typing import Iterable

__all__ = [
    "NUMERIC_TYPES", "POINT_CLOUD", "COMPRESSED_IMAGE", "RAW_IMAGE", "GRID", "FRAME_TRANSFORM", "FRAME_MARKER",
    "struct_schema", "encode_schema",
]

#: foxglove.NumericType values by numpy dtype string
NUMERIC_TYPES = {"u1": 1, "i1": 2, "u2": 3, "i2": 4, "u4": 5, "i4": 6, "f4": 7, "f8": 8}


def _time(desc: str) -> dict:
    return {"type": "object", "title": "time", "description": desc,
            "properties": {"sec": {"type": "integer", "minimum": 0},
                           "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999}}}


def _vector3(desc: str) -> dict:
    return {"title": "foxglove.Vector3", "description": desc, "type": "object",
            "properties": {k: {"type": "number", "description": f"{k} coordinate length"} for k in "xyz"}}


def _quaternion(desc: str) -> dict:
    return {"title": "foxglove.Quaternion", "description": desc, "type": "object",
            "properties": {k: {"type": "number", "description": f"{k} value"} for k in "xyzw"}}


def _pose(desc: str) -> dict:
    return {"title": "foxglove.Pose", "description": desc, "type": "object",
            "properties": {"position": _vector3("Point denoting position in 3D space"),
                           "orientation": _quaternion("Quaternion denoting orientation in 3D space")}}


def _packed_fields(desc: str) -> dict:
    types = [{"title": t, "const": i} for t, i in (("UNKNOWN", 0), ("UINT8", 1), ("INT8", 2), ("UINT16", 3),
                                                    ("INT16", 4), ("UINT32", 5), ("INT32", 6), ("FLOAT32", 7),
                                                    ("FLOAT64", 8))]
    item = {"title": "foxglove.PackedElementField",
            "description": "A field present within each element in a byte array of packed elements.",
            "type": "object",
            "properties": {"name": {"type": "string", "description": "Name of the field"},
                           "offset": {"type": "integer", "minimum": 0,
                                      "description": "Byte offset from start of data buffer"},
                           "type": {"title": "foxglove.NumericType", "oneOf": types,
                                    "description": "Type of data in the field. Integers are stored using "
                                                   "little-endian byte order."}}}
    return {"type": "array", "items": item, "description": desc}


def _bytes(desc: str) -> dict:
    return {"type": "string", "contentEncoding": "base64", "description": desc}


def _message(title: str, desc: str, properties: dict) -> dict:
    return {"title": title, "description": desc, "$comment": "foxglove well-known schema (JSON encoding)",
            "type": "object", "properties": properties}


POINT_CLOUD = _message("foxglove.PointCloud", "A collection of N-dimensional points", {
    "timestamp": _time("Timestamp of point cloud"),
    "frame_id": {"type": "string", "description": "Frame of reference"},
    "pose": _pose("The origin of the point cloud relative to the frame of reference"),
    "point_stride": {"type": "integer", "minimum": 0, "description": "Number of bytes between points in the `data`"},
    "fields": _packed_fields("Fields in `data`"),
    "data": _bytes("Point data, interpreted using `fields`"),
})

COMPRESSED_IMAGE = _message("foxglove.CompressedImage", "A compressed image", {
    "timestamp": _time("Timestamp of image"),
    "frame_id": {"type": "string", "description": "Frame of reference for the image"},
    "data": _bytes("Compressed image data"),
    "format": {"type": "string", "description": "Image format: `png` or `jpeg`"},
})

RAW_IMAGE = _message("foxglove.RawImage", "A raw image", {
    "timestamp": _time("Timestamp of image"),
    "frame_id": {"type": "string", "description": "Frame of reference for the image"},
    "width": {"type": "integer", "minimum": 0, "description": "Image width"},
    "height": {"type": "integer", "minimum": 0, "description": "Image height"},
    "encoding": {"type": "string", "description": "Encoding of the raw image data, e.g. `rgba8`"},
    "step": {"type": "integer", "minimum": 0, "description": "Byte length of a single row"},
    "data": _bytes("Raw image data"),
})

GRID = _message("foxglove.Grid", "A 2D grid of data", {
    "timestamp": _time("Timestamp of grid"),
    "frame_id": {"type": "string", "description": "Frame of reference"},
    "pose": _pose("Origin of grid's corner relative to frame of reference; grid is positioned in the x-y plane "
                  "relative to this origin"),
    "column_count": {"type": "integer", "minimum": 0, "description": "Number of grid columns"},
    "cell_size": {"title": "foxglove.Vector2", "type": "object",
                  "description": "Size of single grid cell along x and y axes, relative to `pose`",
                  "properties": {k: {"type": "number", "description": f"{k} coordinate length"} for k in "xy"}},
    "row_stride": {"type": "integer", "minimum": 0, "description": "Number of bytes between rows in `data`"},
    "cell_stride": {"type": "integer", "minimum": 0,
                    "description": "Number of bytes between cells within a row in `data`"},
    "fields": _packed_fields("Fields in `data`"),
    "data": _bytes("Grid cell data, interpreted using `fields`, in row-major (y-major) order"),
})

FRAME_TRANSFORM = _message("foxglove.FrameTransform", "A transform between two reference frames in 3D space", {
    "timestamp": _time("Timestamp of transform"),
    "parent_frame_id": {"type": "string", "description": "Name of the parent frame"},
    "child_frame_id": {"type": "string", "description": "Name of the child frame"},
    "translation": _vector3("Translation component of the transform"),
    "rotation": _quaternion("Rotation component of the transform"),
})

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


def encode_schema(schema: dict) -> bytes:
    """Canonical UTF-8 JSON bytes of a schema (what goes into the MCAP Schema record)."""
    return json.dumps(schema, sort_keys=True, separators=(",", ":")).encode()
