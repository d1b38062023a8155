"""A lean chunked MCAP writer: messages go from their parts into the chunk buffer with one copy, no join.

mcap's own ``Writer`` copies every message several times (a BytesIO per chunk, another per record, a join of
the message before it) and compresses with fixed settings (zstd level 3 or lz4), which is most of a recorder
frame's CPU time when a frame carries a 0.6 MB LiDAR cloud. :class:`McapFile` writes the same file format
(MCAP v0: the records of ``mcap.records``, chunks with message indexes, a summary with schemas, channels,
statistics, chunk and metadata indexes and summary offsets), so mcap's readers, Foxglove and
:func:`cosim.recording.read_recording` read it as before, with three differences in how:

* :meth:`add_message` takes the message as a sequence of buffers (e.g. a protobuf header and a numpy array's
  memory) and copies them straight into the chunk's bytearray: nothing refers to the caller's buffers after
  the call returns (they may be a frame slot given back right after).
* zstd chunks use a fast level with an 8 MiB window (:data:`ZSTD_WINDOW_LOG`, ~7 default frames), so a LiDAR
  point or image row unchanged since an earlier frame of the chunk (most of them: the sensor and the ground
  stand still) costs a few bytes. ~1.5 GB/s and ~7 x on recorded default frames, against lz4's ~1 GB/s and
  ~2 x (zstd's default fast levels have too small a window and hash table to reach the previous frame).
* The integrity check of a zstd chunk is zstd's own frame checksum (XXH64, computed while compressing, checked
  by every zstd decoder) instead of the chunk's CRC-32 (a separate pass at ~5 GB/s); its ``uncompressed_crc``
  is then 0, which MCAP defines as "not computed". lz4 and uncompressed chunks carry the CRC-32.

Schema and channel records are written into the data section as they are registered (before the first chunk)
and repeated in the summary. Not thread-safe; one writer per file.
"""
from __future__ import annotations

import struct
import zlib
from collections import defaultdict
from typing import BinaryIO, Sequence

import numpy as np
from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (
    Channel,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)

__all__ = ["McapFile", "MAGIC", "COMPRESSIONS", "CHUNK_BYTES", "ZSTD_LEVEL", "ZSTD_WINDOW_LOG", "ZSTD_HASH_LOG",
           "message_index_record"]

#: MCAP v0 magic (start and end of a file)
MAGIC = b"\x89MCAP0\r\n"
#: chunk compressions (MCAP's names; "none" is written as "")
COMPRESSIONS = ("zstd", "lz4", "none")
#: most bytes of records (uncompressed) in a chunk: a message that would not fit closes the chunk first. The
#: writer flushes every 1 s (~11 MB of a default run), so this bounds memory and the chunks of heavy frames
CHUNK_BYTES = 16 * 2**20
#: zstd level of chunks: a fast negative level (~1.5 GB/s on recorded default frames)
ZSTD_LEVEL = -5
#: zstd window, log2 bytes: 8 MiB reaches back ~7 default frames, so repeats across a chunk's frames are found
ZSTD_WINDOW_LOG = 23
#: zstd match-finder hash table, log2 entries (small and fast; larger found no more on recorded frames)
ZSTD_HASH_LOG = 17

#: Message record header: opcode, record length, channel id, sequence, log time, publish time
_MESSAGE = struct.Struct("<BQHIQQ")
_MESSAGE_FIXED = _MESSAGE.size - 9  # the record's own fields before its data
#: Chunk record header up to the compression string: opcode, length, start, end, uncompressed size, crc
_CHUNK_HEAD = struct.Struct("<BQQQQI")
#: Message index record header: opcode, record length, channel id, byte length of the (log time, offset) pairs
_INDEX_HEAD = struct.Struct("<BQHI")


def message_index_record(channel_id: int, index: list[tuple[int, int]]) -> bytes:
    """The MessageIndex record of a chunk's messages on ``channel_id``: (log time ns, offset in the chunk's
    records) pairs, the bytes ``mcap.records.MessageIndex(...).write`` makes, packed in one call instead of two
    ``struct.pack`` per message (a ground-truth run's chunks hold ~8000 messages a second)."""
    pairs = np.array(index, dtype="<u8").reshape(-1, 2)
    return _INDEX_HEAD.pack(Opcode.MESSAGE_INDEX, 2 + 4 + pairs.nbytes, channel_id, pairs.nbytes) + pairs.tobytes()


class McapFile:
    """Writes an MCAP file to ``stream`` (binary, not closed here), chunks compressed with ``compression``.

    Call :meth:`start` first and :meth:`finish` last; :meth:`flush` closes the chunk in progress and flushes the
    stream, so that a reader of the file (or of a copy cut off later) sees every message added before it.
    """

    def __init__(self, stream: BinaryIO, compression: str = "zstd", chunk_bytes: int = CHUNK_BYTES):
        self._stream = stream
        self._pos = 0
        self._chunk_bytes = int(chunk_bytes)
        self._compressor = None
        self._schemas: dict[int, Schema] = {}
        self._channels: dict[int, Channel] = {}
        self._counts: dict[int, int] = defaultdict(int)
        self._messages = 0
        self._t_start = self._t_end = 0
        self._chunk_indexes: list[ChunkIndex] = []
        self._metadata_indexes: list[MetadataIndex] = []
        self._metadata_count = 0
        # the chunk in progress: its records (the first _n bytes of a buffer allocated once and reused: growing a
        # bytearray copies it again and again), message index {channel: [(log time, offset)]} and time range
        self._buf = bytearray(self._chunk_bytes)
        self._mv = memoryview(self._buf)
        self._n = 0
        self._index: dict[int, list[tuple[int, int]]] = {}
        self._c_start = self._c_end = 0
        self.compression = ""
        self.set_compression(compression)

    # -- records outside chunks ----------------------------------------------------------------------------
    def _write(self, data) -> None:
        self._stream.write(data)
        self._pos += len(data)

    def _write_record(self, record) -> int:
        """Write one ``mcap.records`` record; returns its length in bytes."""
        rb = RecordBuilder()
        record.write(rb)
        data = rb.end()
        self._write(data)
        return len(data)

    def start(self, profile: str, library: str) -> None:
        self._write(MAGIC)
        self._write_record(Header(profile, library))

    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        sid = len(self._schemas) + 1
        self._schemas[sid] = Schema(id=sid, name=name, encoding=encoding, data=data)
        self._write_record(self._schemas[sid])
        return sid

    def register_channel(self, topic: str, message_encoding: str, schema_id: int) -> int:
        cid = len(self._channels) + 1
        self._channels[cid] = Channel(id=cid, topic=topic, message_encoding=message_encoding, schema_id=schema_id,
                                      metadata={})
        self._write_record(self._channels[cid])
        return cid

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        """A Metadata record (between chunks: the chunk in progress is closed first)."""
        self._finish_chunk()
        offset = self._pos
        length = self._write_record(Metadata(name=name, metadata=dict(data)))
        self._metadata_indexes.append(MetadataIndex(offset=offset, length=length, name=name))
        self._metadata_count += 1

    # -- messages and chunks -------------------------------------------------------------------------------
    def set_compression(self, compression: str) -> None:
        """Compress the chunks from the next one on with ``compression`` (closes the chunk in progress if it
        changes)."""
        if compression not in COMPRESSIONS:
            raise ValueError(f"chunk compression must be one of {COMPRESSIONS}, got {compression!r}")
        name = "" if compression == "none" else compression
        if name != self.compression:
            self._finish_chunk()
            self.compression = name
        if name == "zstd" and self._compressor is None:
            import zstandard

            params = zstandard.ZstdCompressionParameters.from_level(
                ZSTD_LEVEL, window_log=ZSTD_WINDOW_LOG, hash_log=ZSTD_HASH_LOG, write_checksum=True,
                write_content_size=True)
            self._compressor = zstandard.ZstdCompressor(compression_params=params)

    def add_message(self, channel_id: int, log_time: int, parts: Sequence, publish_time: int | None = None) -> None:
        """Add a message whose data is the concatenation of ``parts`` (bytes or any C-contiguous buffers; copied
        here, not kept)."""
        views = [p if type(p) is bytes else memoryview(p).cast("B") for p in parts]
        size = sum(map(len, views))
        need = _MESSAGE.size + size
        if self._n + need > len(self._buf):
            self._finish_chunk()
            if need > len(self._buf):  # one message larger than a chunk: a buffer of its size, for this chunk
                self._mv.release()
                self._buf = bytearray(need)
                self._mv = memoryview(self._buf)
        if not self._index:
            self._c_start = self._c_end = log_time
        elif log_time > self._c_end:
            self._c_end = log_time
        elif log_time < self._c_start:
            self._c_start = log_time
        n = self._n
        index = self._index.get(channel_id)
        if index is None:
            index = self._index[channel_id] = []
        index.append((log_time, n))
        _MESSAGE.pack_into(self._buf, n, Opcode.MESSAGE, _MESSAGE_FIXED + size, channel_id, 0, log_time,
                           log_time if publish_time is None else publish_time)
        n += _MESSAGE.size
        mv = self._mv
        for v in views:
            k = n + len(v)
            mv[n:k] = v
            n = k
        self._n = n
        if self._messages == 0:
            self._t_start = self._t_end = log_time
        elif log_time > self._t_end:
            self._t_end = log_time
        elif log_time < self._t_start:
            self._t_start = log_time
        self._messages += 1
        self._counts[channel_id] += 1

    def _finish_chunk(self) -> None:
        if not self._index:
            return
        records = self._mv[:self._n]
        if self.compression == "zstd":
            data, crc = self._compressor.compress(records), 0  # zstd's frame checksum guards the content
        elif self.compression == "lz4":
            import lz4.frame

            data, crc = lz4.frame.compress(records), zlib.crc32(records)
        else:
            data, crc = records, zlib.crc32(records)
        comp = self.compression.encode()
        head = _CHUNK_HEAD.pack(Opcode.CHUNK, 8 * 3 + 4 + 4 + len(comp) + 8 + len(data), self._c_start, self._c_end,
                                self._n, crc) + struct.pack("<I", len(comp)) + comp + struct.pack("<Q", len(data))
        start = self._pos
        self._write(head)
        self._write(data)
        chunk_length = self._pos - start
        parts, offsets, n = [], {}, 0
        for cid, index in self._index.items():
            offsets[cid] = self._pos + n
            record = message_index_record(cid, index)
            parts.append(record)
            n += len(record)
        index_bytes = b"".join(parts)
        self._write(index_bytes)
        self._chunk_indexes.append(ChunkIndex(
            message_start_time=self._c_start, message_end_time=self._c_end, chunk_start_offset=start,
            chunk_length=chunk_length, message_index_offsets=offsets, message_index_length=len(index_bytes),
            compression=self.compression, compressed_size=len(data), uncompressed_size=self._n))
        records.release()
        if len(self._buf) > self._chunk_bytes:  # back to the usual size after an outsized message
            self._mv.release()
            self._buf = bytearray(self._chunk_bytes)
            self._mv = memoryview(self._buf)
        self._n = 0
        self._index = {}

    def flush(self) -> None:
        """Close the chunk in progress (if it has a message) and flush the stream."""
        self._finish_chunk()
        self._stream.flush()

    def finish(self) -> None:
        """Close the last chunk and write the data end, the summary and the footer (the stream stays open)."""
        self._finish_chunk()
        self._write_record(DataEnd(0))
        summary_start = self._pos
        rb = RecordBuilder()
        offsets = []

        def group(opcode, records) -> None:
            first = rb.count
            for r in records:
                r.write(rb)
            offsets.append(SummaryOffset(group_opcode=opcode, group_start=summary_start + first,
                                         group_length=rb.count - first))

        group(Opcode.SCHEMA, self._schemas.values())
        group(Opcode.CHANNEL, self._channels.values())
        group(Opcode.STATISTICS, [Statistics(
            message_count=self._messages, schema_count=len(self._schemas), channel_count=len(self._channels),
            attachment_count=0, metadata_count=self._metadata_count, chunk_count=len(self._chunk_indexes),
            message_start_time=self._t_start, message_end_time=self._t_end,
            channel_message_counts=dict(self._counts))])
        group(Opcode.CHUNK_INDEX, self._chunk_indexes)
        group(Opcode.METADATA_INDEX, self._metadata_indexes)
        offset_start = summary_start + rb.count
        for o in offsets:
            o.write(rb)
        summary = rb.end()
        crc = zlib.crc32(struct.pack("<BQQQ", Opcode.FOOTER, 8 + 8 + 4, summary_start, offset_start),
                         zlib.crc32(summary))
        self._write(summary)
        self._write_record(Footer(summary_start=summary_start, summary_offset_start=offset_start, summary_crc=crc))
        self._write(MAGIC)
        self._stream.flush()
