"""JSON-schema definitions of this project's own channels (JSON message encoding).

Foxglove's well-known messages (PointCloud, RawImage, CompressedImage, Grid, FrameTransform) are written in
protobuf by foxglove-sdk. Our own: ``cosim.struct.<block>`` (one scalar
time series message per struct block and frame, field descriptions carrying units; Foxglove plots these) and
``cosim.Frame`` (the end-of-frame marker that makes a killed run's file readable up to its last completed
frame). Timestamps are Foxglove's JSON time ``{sec, nsec}``.
"""
from __future__ import annotations

import json
from typing import Iterable

__all__ = ["FRAME_MARKER", "struct_schema", "marker_json"]


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
    sec, nsec = divmod(max(0, int(t_ns)), 1_000_000_000)
    return json.dumps({"timestamp": {"sec": sec, "nsec": nsec}, "frame": int(frame), "t_s": float(t_s)},
                      separators=(",", ":")).encode()
