"""Derived layout of a run's segment: header, encoded schema, 64-byte aligned blocks, fingerprint.

Nothing here is written by hand: the header is a numpy structured dtype, block offsets follow from the
declarations in order, and the fingerprint is a hash of the canonical msgpack encoding of the schema.

Segment layout::

    [header: HEADER_DTYPE][schema: msgpack bytes][pad to 64]
    for each block: [block header: BLOCK_HEADER_DTYPE, 64 bytes][data, padded to 64]
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass
from typing import Iterable, Sequence

import msgpack
import numpy as np

from .spec import ArrayBlock, Block, Field, SchemaError, StructBlock, check_name

__all__ = [
    "ALIGN", "MAGIC", "LAYOUT_VERSION", "ACTIVITY_BYTES", "MAX_PROCS", "ERROR_BYTES", "PROC_DTYPE", "HEADER_DTYPE",
    "BLOCK_HEADER_DTYPE", "BLOCK_WORD", "SLOT_WORD", "BlockLayout", "Schema", "align_up",
]

ALIGN = 64
MAGIC = b"COSIMSHM"
#: 2: process slots gained ``alive_ns`` (the liveness heartbeat, beside the per-step ``heartbeat_ns``); 3: and
#: ``beat_tid`` (the heartbeat thread, left out of the CPU evidence of progress) and ``activity`` (what a starting
#: process is doing, for the start-up report)
LAYOUT_VERSION = 3
#: bytes of a process slot's ``activity`` text (UTF-8, NUL-padded)
ACTIVITY_BYTES = 48
#: process slots in the header: the ring participants plus the supervisor and spares for stand-ins
MAX_PROCS = 6
#: bytes reserved per process for a msgpack-encoded error report (type, message, traceback)
ERROR_BYTES = 8192

PROC_DTYPE = np.dtype(
    [
        ("name", "S16"),
        ("pid", "<i8"),
        ("phase", "<i8"),
        ("frame", "<i8"),
        ("heartbeat_ns", "<i8"),
        ("token", "<i8"),
        ("step_ns", "<i8"),
        #: CLOCK_MONOTONIC ns of the process's last liveness beat (a thread beside its frame work,
        #: cosim.runtime.liveness); ``heartbeat_ns`` is the time of its last step boundary
        ("alive_ns", "<i8"),
        #: the kernel's thread id of the heartbeat thread (its CPU time is not evidence of the process's progress)
        ("beat_tid", "<i8"),
        #: what the process is doing while it starts ("compiling shaders"), set by cosim.runtime.participant.activity
        ("activity", f"S{ACTIVITY_BYTES}"),
        ("error_len", "<i8"),
        ("error", f"S{ERROR_BYTES}"),
    ],
    align=True,
)

#: index of each int64 field of a process slot in :meth:`Segment.slot_words` (derived from PROC_DTYPE)
SLOT_WORD = {name: PROC_DTYPE.fields[name][1] // 8 for name in PROC_DTYPE.names
             if PROC_DTYPE.fields[name][0] == np.dtype("<i8")}

HEADER_DTYPE = np.dtype(
    [
        ("magic", "S8"),
        ("layout_version", "<u4"),
        ("n_procs", "<u4"),
        ("fingerprint", "S32"),
        ("run_id", "S32"),
        ("schema_offset", "<u8"),
        ("schema_nbytes", "<u8"),
        ("total_nbytes", "<u8"),
        ("run_state", "<i8"),
        ("frames", "<i8"),
        ("procs", PROC_DTYPE, (MAX_PROCS,)),
    ],
    align=True,
)

BLOCK_HEADER_DTYPE = np.dtype({"names": ["seq", "frame", "t_ns"], "formats": ["<u8", "<i8", "<i8"],
                               "itemsize": ALIGN})
#: index of each field of a block header read as int64 words (derived from BLOCK_HEADER_DTYPE; seq is unsigned
#: in the layout and stays far below 2**63, so both readings agree)
BLOCK_WORD = {name: BLOCK_HEADER_DTYPE.fields[name][1] // 8 for name in BLOCK_HEADER_DTYPE.names}


def align_up(n: int, a: int = ALIGN) -> int:
    """Smallest multiple of ``a`` that is >= ``n``."""
    return (n + a - 1) // a * a


@dataclass(frozen=True)
class BlockLayout:
    """Where one block lives: its block header at ``offset``, its data at ``data_offset`` (bytes from start)."""

    block: Block
    offset: int
    data_offset: int
    nbytes: int


def _describe(block: Block) -> dict:
    """Canonical, msgpack-able description of a block (what the fingerprint covers)."""
    if isinstance(block, StructBlock):
        return {"kind": "struct", "name": block.name, "writer": block.writer, "doc": block.doc,
                "fields": [[f.name, f.unit, f.dtype, f.doc] for f in block.fields]}
    return {"kind": block.kind, "name": block.name, "writer": block.writer, "doc": block.doc,
            "dtype": block.dtype, "shape": list(block.shape), "unit": block.unit}


def _undescribe(d: dict) -> Block:
    if d["kind"] == "struct":
        fields = tuple(Field(n, u, t, doc) for n, u, t, doc in d["fields"])
        return StructBlock(d["name"], d["writer"], fields, d.get("doc", ""))
    return ArrayBlock(d["name"], d["writer"], d["dtype"], tuple(d["shape"]), d.get("unit", ""), d.get("doc", ""),
                      d["kind"])


class Schema:
    """An ordered set of blocks with one writer each, and the participants allowed to write.

    ``participants`` are the process names that own header slots (ring members and the supervisor). Every
    block's writer must be one of them. Layout, encoded bytes and fingerprint are derived once, here.
    """

    def __init__(self, blocks: Iterable[Block], participants: Sequence[str]):
        self.blocks: tuple[Block, ...] = tuple(blocks)
        self.participants: tuple[str, ...] = tuple(check_name("participant", p) for p in participants)
        if len(set(self.participants)) != len(self.participants):
            raise SchemaError(f"participants repeat: {self.participants}")
        if len(self.participants) > MAX_PROCS:
            raise SchemaError(f"{len(self.participants)} participants exceed the {MAX_PROCS} header slots")
        names = [b.name for b in self.blocks]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise SchemaError(f"blocks declared twice: {dup}")
        for b in self.blocks:
            if b.writer not in self.participants:
                raise SchemaError(f"block {b.name!r}: writer {b.writer!r} is not a participant {self.participants}")
        self.encoded: bytes = msgpack.packb(
            {"participants": list(self.participants), "blocks": [_describe(b) for b in self.blocks]},
            use_bin_type=True,
        )
        self.fingerprint: str = hashlib.blake2b(self.encoded, digest_size=16).hexdigest()
        self.schema_offset = align_up(HEADER_DTYPE.itemsize)
        offset = align_up(self.schema_offset + len(self.encoded))
        layouts = {}
        for b in self.blocks:
            layouts[b.name] = BlockLayout(b, offset, offset + ALIGN, b.nbytes)
            offset = align_up(offset + ALIGN + b.nbytes)
        self.layout: dict[str, BlockLayout] = layouts
        self.total_nbytes: int = offset

    @classmethod
    def decode(cls, encoded: bytes) -> "Schema":
        """Rebuild a schema from the bytes stored in a segment."""
        d = msgpack.unpackb(encoded, raw=False)
        return cls([_undescribe(b) for b in d["blocks"]], d["participants"])

    def block(self, name: str) -> Block:
        try:
            return self.layout[name].block
        except KeyError:
            raise KeyError(f"no block {name!r} in this schema; blocks: {sorted(self.layout)}") from None

    def __contains__(self, name: str) -> bool:
        return name in self.layout

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Schema) and other.fingerprint == self.fingerprint

    def __hash__(self) -> int:
        return hash(self.fingerprint)

    def __repr__(self) -> str:
        return f"Schema({len(self.blocks)} blocks, {self.total_nbytes} bytes, fingerprint {self.fingerprint[:12]})"
