"""Foxglove's well-known schemas in protobuf wire format, written and read without the protobuf package.

Foxglove, Lichtblick and the MCAP tools read a ``protobuf`` channel from its schema record, a serialized
``google.protobuf.FileDescriptorSet`` of the message's ``.proto`` files. :data:`MESSAGES` transcribes the few
messages this recorder writes from foxglove/schemas (``schemas/proto/foxglove/*.proto``: names, field numbers
and types exactly as there, without the newer optional ``uuid``/``lineage`` extras); everything else is derived
from it: :func:`descriptor_set` (the schema record), :func:`encode` (dict -> message bytes) and :func:`decode`
(message bytes -> dict). ``bytes`` fields are written as given (any buffer, no copy before the final join), so
a 1 MB image costs one memcpy instead of base64 and JSON. ``google.protobuf.Timestamp`` {seconds, nanos} is
built and returned as ``{"sec", "nsec"}``, the name Foxglove uses in its JSON and TypeScript schemas.

tests/test_recording_proto.py checks all three against the protobuf package as an independent decoder.
"""
from __future__ import annotations

import struct
from typing import NamedTuple

import numpy as np

__all__ = ["Field", "MESSAGES", "ENUMS", "FILES", "descriptor_set", "encode", "encode_parts", "decode", "varint",
           "ProtoError"]


class ProtoError(ValueError):
    """Bytes that are not a well-formed message of the expected type."""


class Field(NamedTuple):
    """One message field: its name, number, scalar type or message/enum type name, and repetition."""

    name: str
    number: int
    type: str  # double | fixed32 | int32 | int64 | string | bytes | enum:<full name> | <message full name>
    repeated: bool = False


_TS = "google.protobuf.Timestamp"
_POSE, _V3, _Q, _V2, _PEF = "foxglove.Pose", "foxglove.Vector3", "foxglove.Quaternion", "foxglove.Vector2", \
    "foxglove.PackedElementField"
_NUMERIC = "foxglove.PackedElementField.NumericType"

#: message full name -> fields (transcribed from foxglove/schemas proto files and google/protobuf/timestamp.proto)
MESSAGES: dict[str, tuple[Field, ...]] = {
    _TS: (Field("seconds", 1, "int64"), Field("nanos", 2, "int32")),
    _V2: (Field("x", 1, "double"), Field("y", 2, "double")),
    _V3: (Field("x", 1, "double"), Field("y", 2, "double"), Field("z", 3, "double")),
    _Q: (Field("x", 1, "double"), Field("y", 2, "double"), Field("z", 3, "double"), Field("w", 4, "double")),
    _POSE: (Field("position", 1, _V3), Field("orientation", 2, _Q)),
    _PEF: (Field("name", 1, "string"), Field("offset", 2, "fixed32"), Field("type", 3, f"enum:{_NUMERIC}")),
    "foxglove.PointCloud": (Field("timestamp", 1, _TS), Field("frame_id", 2, "string"), Field("pose", 3, _POSE),
                            Field("point_stride", 4, "fixed32"), Field("fields", 5, _PEF, True),
                            Field("data", 6, "bytes")),
    "foxglove.RawImage": (Field("timestamp", 1, _TS), Field("frame_id", 7, "string"), Field("width", 2, "fixed32"),
                          Field("height", 3, "fixed32"), Field("encoding", 4, "string"),
                          Field("step", 5, "fixed32"), Field("data", 6, "bytes")),
    "foxglove.CompressedImage": (Field("timestamp", 1, _TS), Field("frame_id", 4, "string"),
                                 Field("data", 2, "bytes"), Field("format", 3, "string")),
    "foxglove.Grid": (Field("timestamp", 1, _TS), Field("frame_id", 2, "string"), Field("pose", 3, _POSE),
                      Field("column_count", 4, "fixed32"), Field("cell_size", 5, _V2),
                      Field("row_stride", 6, "fixed32"), Field("cell_stride", 7, "fixed32"),
                      Field("fields", 8, _PEF, True), Field("data", 9, "bytes")),
    "foxglove.FrameTransform": (Field("timestamp", 1, _TS), Field("parent_frame_id", 2, "string"),
                                Field("child_frame_id", 3, "string"), Field("translation", 4, _V3),
                                Field("rotation", 5, _Q)),
}
#: enum full name -> (value name, number) pairs; nested in the message before its last dot
ENUMS: dict[str, tuple[tuple[str, int], ...]] = {
    _NUMERIC: (("UNKNOWN", 0), ("UINT8", 1), ("INT8", 2), ("UINT16", 3), ("INT16", 4), ("UINT32", 5),
               ("INT32", 6), ("FLOAT32", 7), ("FLOAT64", 8)),
}
#: top-level message -> its .proto file, as in foxglove/schemas
FILES: dict[str, str] = {_TS: "google/protobuf/timestamp.proto",
                         **{m: f"foxglove/{m.split('.')[1]}.proto" for m in MESSAGES if m.startswith("foxglove.")}}

# wire types and descriptor.proto numbers (FieldDescriptorProto.Type / Label)
_VARINT, _I64, _LEN, _I32 = 0, 1, 2, 5
_SCALAR = {"double": (_I64, 1), "int64": (_VARINT, 3), "int32": (_VARINT, 5), "fixed32": (_I32, 7),
           "string": (_LEN, 9), "bytes": (_LEN, 12)}
_TYPE_MESSAGE, _TYPE_ENUM, _LABEL_OPTIONAL, _LABEL_REPEATED = 11, 14, 1, 3
_DOUBLE, _FIXED32 = struct.Struct("<d"), struct.Struct("<I")


def varint(n: int) -> bytes:
    """Protobuf base-128 varint of ``n`` (a negative int32/int64 as its 64-bit two's complement)."""
    if 0 <= n < 128:
        return _SMALL[n]
    n &= (1 << 64) - 1  # negative int32/int64: two's complement, 10 bytes
    out = bytearray()
    while n > 0x7F:
        out.append((n & 0x7F) | 0x80)
        n >>= 7
    out.append(n)
    return bytes(out)


_SMALL = [bytes((i,)) for i in range(128)]


def _len_field(number: int, payload: bytes) -> list:
    return [varint(number << 3 | _LEN), varint(len(payload)), payload]


def _flat(buf):
    """A C-contiguous buffer (numpy arrays of any dtype and shape included) as flat bytes, without a copy."""
    if isinstance(buf, np.ndarray):
        return memoryview(np.ascontiguousarray(buf).reshape(-1).view(np.uint8))
    return memoryview(buf).cast("B")


def _plan(name: str) -> tuple:
    """(field name, kind, key bytes, type, repeated) per field of ``name``: the encoder's per-message table."""
    plan = []
    for f in MESSAGES[name]:
        if f.type in ("double", "fixed32"):
            kind, wire = f.type, _I64 if f.type == "double" else _I32
        elif f.type in ("int32", "int64") or f.type.startswith("enum:"):
            kind, wire = "varint", _VARINT
        else:
            kind, wire = ("string" if f.type == "string" else "bytes" if f.type == "bytes" else "message"), _LEN
        plan.append((f.name, kind, varint(f.number << 3 | wire), f.type, f.repeated))
    return tuple(plan)


def _encode_parts(name: str, msg: dict, out: list) -> None:
    for fname, kind, key, ftype, repeated in _PLANS[name]:
        value = msg.get(fname)
        if value is None:
            continue
        for v in (value if repeated else (value,)):
            if kind == "double":
                out += (key, _DOUBLE.pack(v))
            elif kind == "fixed32":
                out += (key, _FIXED32.pack(v))
            elif kind == "varint":
                out += (key, varint(int(v)))
            else:
                if kind == "string":
                    v = v.encode()
                elif kind == "message":
                    v = encode(ftype, v)
                elif not isinstance(v, bytes):
                    v = _flat(v)
                out += (key, varint(len(v)), v)


_PLANS = {name: _plan(name) for name in MESSAGES}


def encode_parts(name: str, msg: dict) -> list:
    """The wire bytes of message ``name`` as a list of buffers whose concatenation is :func:`encode`'s result:
    ``bytes`` fields given as buffers (a numpy array's memory) stay themselves, uncopied, so a writer can copy
    them once into its destination (valid while those buffers are)."""
    if name == _TS:
        msg = {"seconds": msg["sec"], "nanos": msg["nsec"]}
    parts: list = []
    _encode_parts(name, msg, parts)
    return parts


def encode(name: str, msg: dict) -> bytes:
    """Wire bytes of message ``name`` from a dict of its fields (missing or None fields are left out).

    Messages are dicts, repeated fields lists, ``bytes`` fields any C-contiguous buffer (numpy arrays as their
    raw bytes); a Timestamp is ``{"sec", "nsec"}``.
    """
    return b"".join(encode_parts(name, msg))


def _read_varint(buf: memoryview, i: int) -> tuple[int, int]:
    shift = result = 0
    while True:
        if i >= len(buf):
            raise ProtoError("message ends inside a varint")
        b = buf[i]
        i += 1
        result |= (b & 0x7F) << shift
        if not b & 0x80:
            return result, i
        shift += 7


def _signed(n: int, bits: int) -> int:
    n &= (1 << bits) - 1
    return n - (1 << bits) if n >> (bits - 1) else n


def _default(f: Field):
    if f.repeated:
        return []
    if f.type in ("double",):
        return 0.0
    if f.type in ("string",):
        return ""
    if f.type == "bytes":
        return b""
    if f.type in _SCALAR or f.type.startswith("enum:"):
        return 0
    return decode(f.type, b"")


def decode(name: str, data) -> dict:
    """Dict of message ``name`` from its wire bytes; absent fields get proto3 defaults, unknown fields are skipped."""
    fields = {f.number: f for f in MESSAGES[name]}
    buf = memoryview(data).cast("B")
    out: dict = {}
    i = 0
    while i < len(buf):
        key, i = _read_varint(buf, i)
        number, wire = key >> 3, key & 7
        if wire == _VARINT:
            raw, i = _read_varint(buf, i)
        elif wire == _I64:
            raw, i = bytes(buf[i:i + 8]), i + 8
        elif wire == _I32:
            raw, i = bytes(buf[i:i + 4]), i + 4
        elif wire == _LEN:
            n, i = _read_varint(buf, i)
            raw, i = buf[i:i + n], i + n
        else:
            raise ProtoError(f"{name}: unsupported wire type {wire} for field {number}")
        if i > len(buf):
            raise ProtoError(f"{name}: field {number} runs past the end of the message")
        f = fields.get(number)
        if f is None:
            continue
        if f.type == "double":
            v = _DOUBLE.unpack(raw)[0]
        elif f.type == "fixed32":
            v = _FIXED32.unpack(raw)[0]
        elif f.type in ("int32", "int64"):
            v = _signed(raw, 32 if f.type == "int32" else 64)
        elif f.type.startswith("enum:"):
            v = raw
        elif f.type == "string":
            v = bytes(raw).decode()
        elif f.type == "bytes":
            v = bytes(raw)
        else:
            v = decode(f.type, raw)
        if f.repeated:
            out.setdefault(f.name, []).append(v)
        else:
            out[f.name] = v
    for f in MESSAGES[name]:
        if f.name not in out:
            out[f.name] = _default(f)
    if name == _TS:
        return {"sec": out["seconds"], "nsec": out["nanos"]}
    return out


# -- descriptors ---------------------------------------------------------------------------------------------
def _field_descriptor(f: Field) -> bytes:
    if f.type in _SCALAR:
        kind, type_name = _SCALAR[f.type][1], None
    elif f.type.startswith("enum:"):
        kind, type_name = _TYPE_ENUM, f.type[len("enum:"):]
    else:
        kind, type_name = _TYPE_MESSAGE, f.type
    parts = _len_field(1, f.name.encode()) + [varint(3 << 3), varint(f.number),
                                              varint(4 << 3), varint(_LABEL_REPEATED if f.repeated else
                                                                       _LABEL_OPTIONAL),
                                              varint(5 << 3), varint(kind)]
    if type_name is not None:
        parts += _len_field(6, f".{type_name}".encode())
    parts += _len_field(10, _json_name(f.name).encode())
    return b"".join(parts)


def _json_name(name: str) -> str:
    head, *rest = name.split("_")
    return head + "".join(p[:1].upper() + p[1:] for p in rest)


def _enum_descriptor(full: str) -> bytes:
    parts = _len_field(1, full.rpartition(".")[2].encode())
    for value, number in ENUMS[full]:
        parts += _len_field(2, b"".join(_len_field(1, value.encode()) + [varint(2 << 3), varint(number)]))
    return b"".join(parts)


def _message_descriptor(full: str) -> bytes:
    parts = _len_field(1, full.rpartition(".")[2].encode())
    for f in MESSAGES[full]:
        parts += _len_field(2, _field_descriptor(f))
    for e in ENUMS:
        if e.rpartition(".")[0] == full:
            parts += _len_field(4, _enum_descriptor(e))
    return b"".join(parts)


def _deps(full: str) -> list[str]:
    """Top-level messages ``full`` refers to, directly."""
    out = []
    for f in MESSAGES[full]:
        t = f.type[len("enum:"):].rpartition(".")[0] if f.type.startswith("enum:") else f.type
        if t in MESSAGES and t != full and t not in out:
            out.append(t)
    return out


def _file_descriptor(full: str) -> bytes:
    package = full.rpartition(".")[0]
    parts = _len_field(1, FILES[full].encode()) + _len_field(2, package.encode())
    for d in _deps(full):
        parts += _len_field(3, FILES[d].encode())
    parts += _len_field(4, _message_descriptor(full)) + _len_field(12, b"proto3")
    return b"".join(parts)


def descriptor_set(name: str) -> bytes:
    """Serialized FileDescriptorSet of message ``name`` and every file it depends on, dependencies first
    (the MCAP ``protobuf`` schema record)."""
    order: list[str] = []

    def visit(m: str) -> None:
        for d in _deps(m):
            visit(d)
        if m not in order:
            order.append(m)

    visit(name)
    return b"".join(b"".join(_len_field(1, _file_descriptor(m))) for m in order)
