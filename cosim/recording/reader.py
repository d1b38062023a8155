"""Reading a recording back: every message of every completed frame, also from a file cut off mid-write.

Messages come back as dicts: JSON channels as parsed, protobuf channels (Foxglove's schemas) parsed with the
protobuf package from the message types the file's own schema records describe (what Foxglove does), every
field present (defaults included), ``bytes`` fields as bytes, timestamps as ``{sec, nsec}``.

A finished file has a summary and an index; a file of a run that was killed has neither and may end inside a
record. :func:`read_recording` therefore reads the data section in file order with mcap's non-seeking reader,
stops at the first damaged record, and keeps only the frames whose end-of-frame marker (``/cosim/frame``) was
written: everything up to the last completed frame, nothing of a frame half written.
"""
from __future__ import annotations

import json
import struct
from dataclasses import dataclass, field
from pathlib import Path

from .writer import FRAME_TOPIC

__all__ = ["Channel", "Recording", "read_recording", "RecordingError"]


class RecordingError(ValueError):
    """The file is not a recording of this project (not MCAP, or no frame in it)."""


@dataclass(frozen=True)
class Channel:
    """One topic of a recording: its schema name and message encoding (``json`` or ``protobuf``)."""

    topic: str
    schema: str
    encoding: str


@dataclass
class Recording:
    """Decoded messages by topic, in file order, as (log_time_ns, message dict) pairs."""

    path: Path
    channels: dict[str, Channel]
    messages: dict[str, list[tuple[int, dict]]]
    #: completed frames (from the end-of-frame markers), in order
    frames: list[int]
    #: the file ended without its summary (the writer did not finish: the run was killed)
    truncated: bool
    metadata: dict[str, dict] = field(default_factory=dict)

    def topic(self, name: str) -> list[tuple[int, dict]]:
        """Messages of ``name``; KeyError naming the topics there are."""
        try:
            return self.messages[name]
        except KeyError:
            raise KeyError(f"no topic {name!r} in {self.path.name}; topics: {sorted(self.messages)}") from None

    def by_schema(self, schema: str) -> list[str]:
        """Topics whose schema is ``schema`` (e.g. ``foxglove.PointCloud``), sorted."""
        return sorted(t for t, c in self.channels.items() if c.schema == schema)


def _message_class(name: str, descriptor_set: bytes):
    """The protobuf message class ``name`` from a serialized FileDescriptorSet (an MCAP protobuf schema)."""
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

    pool = descriptor_pool.DescriptorPool()
    for fd in descriptor_pb2.FileDescriptorSet.FromString(descriptor_set).file:
        pool.Add(fd)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(name))


def _as_dict(m) -> dict:
    """Every field of protobuf message ``m`` (defaults included) as plain values; Timestamps as {sec, nsec}."""
    if m.DESCRIPTOR.full_name == "google.protobuf.Timestamp":
        return {"sec": m.seconds, "nsec": m.nanos}
    out = {}
    for fd in m.DESCRIPTOR.fields:
        v = getattr(m, fd.name)
        # protobuf >= 6.31 has is_repeated, older ones only label
        rep = fd.is_repeated if hasattr(fd, "is_repeated") else fd.label == fd.LABEL_REPEATED
        if fd.message_type is not None:
            v = [_as_dict(x) for x in v] if rep else _as_dict(v)
        elif rep:
            v = list(v)
        out[fd.name] = v
    return out


def _decode(ch: Channel, data: bytes, classes: dict) -> dict:
    if ch.encoding == "json":
        return json.loads(data)
    if ch.encoding == "protobuf" and ch.schema in classes:
        return _as_dict(classes[ch.schema].FromString(data))
    raise RecordingError(f"topic {ch.topic}: cannot decode {ch.encoding!r} messages of schema {ch.schema!r}")


def read_recording(path: Path | str) -> Recording:
    """Read ``path`` (finished or cut off) up to its last completed frame."""
    from mcap.exceptions import McapError
    from mcap.records import Channel as ChannelRecord
    from mcap.records import Footer, Message, Metadata, Schema
    from mcap.stream_reader import StreamReader

    path = Path(path)
    schemas: dict[int, str] = {}
    classes: dict[str, type] = {}
    channels: dict[int, Channel] = {}
    messages: dict[str, list[tuple[int, dict]]] = {}
    metadata: dict[str, dict] = {}
    order: list[tuple[str, int, dict]] = []
    footer = False
    with open(path, "rb") as f:
        try:
            for rec in StreamReader(f, skip_magic=False).records:
                if isinstance(rec, Schema):
                    schemas[rec.id] = rec.name
                    if rec.encoding == "protobuf" and rec.name not in classes:
                        classes[rec.name] = _message_class(rec.name, rec.data)
                elif isinstance(rec, ChannelRecord):
                    channels[rec.id] = Channel(rec.topic, schemas.get(rec.schema_id, ""), rec.message_encoding)
                elif isinstance(rec, Message):
                    ch = channels[rec.channel_id]
                    order.append((ch.topic, rec.log_time, _decode(ch, rec.data, classes)))
                elif isinstance(rec, Metadata):
                    metadata[rec.name] = dict(rec.metadata)
                elif isinstance(rec, Footer):
                    footer = True
        except (McapError, struct.error, EOFError, ValueError, KeyError) as exc:
            if not order and not channels:
                raise RecordingError(f"{path} is not a readable MCAP recording: {type(exc).__name__}: {exc}") from exc
    markers = [(t, m) for topic, t, m in order if topic == FRAME_TOPIC]
    if not markers and not footer:
        raise RecordingError(f"{path} holds no completed frame")
    # a frame's messages precede its marker: drop what follows the last marker (a frame half written)
    cut = max((i for i, (topic, _, _) in enumerate(order) if topic == FRAME_TOPIC), default=-1)
    for topic, t, m in order[:cut + 1]:
        messages.setdefault(topic, []).append((t, m))
    return Recording(path, {c.topic: c for c in channels.values()}, messages, [int(m["frame"]) for _, m in markers],
                     truncated=not footer, metadata=metadata)
