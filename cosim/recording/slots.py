"""Frame slots: a small shared-memory ring through which the sink hands whole frames to the recorder process.

The sink (in the supervisor, while it holds the token) copies the recorded blocks of a completed frame into
slot ``k`` (one memcpy of each block's bytes, no pickling, no per-block seqlock), writes the slot's descriptor
row (the sink call's frame and each block's stamp, the frame its contents belong to; -1 for a block not in
this frame) and then the count of frames put so far. The slot of the n-th frame put is ``n % slots``.

Who may touch a slot when: the sink owns slot ``k`` from the moment it takes a credit for it until it counts
the frame as put; the recorder owns it from when it learns of that count (a message down the pipe: a system
call, so every store before it is visible after it) until it gives the credit back. A slot is therefore never
read while it is written, and needs no seqlock. The count in shared memory is for one case only: when the
launcher is killed, the recorder sees its pipe close and takes every frame counted (the dead launcher's stores
are all done) even if no message told it of the last ones; the sink may batch its messages.

The slots are a :class:`shm_schema.Segment` of their own: slot ``k`` of run block ``b`` is block ``s<k>_<b>``,
next to the descriptor and count blocks, so layout, named views, attach with fingerprint check and the
creator-only unlink all come from ``shm_schema``; nothing here computes an offset.
"""
from __future__ import annotations

import dataclasses
import os
import secrets

import numpy as np

from shm_schema import ArrayBlock, Schema, Segment, StructBlock

from .writer import FrameData

__all__ = ["FrameSlots", "SLOT_WRITER", "DESCRIPTOR_BLOCK", "COUNT_BLOCK", "NOT_PUT", "slot_schema", "slot_block",
           "block_bytes"]

#: the (only) writer of the slot segment's blocks: the recording sink
SLOT_WRITER = "sink"
#: block of the slot descriptors, (slots, 1 + blocks) int64: the sink call's frame, then each block's stamp
DESCRIPTOR_BLOCK = "slot_descriptor"
#: block of the count of frames put so far, (1,) int64
COUNT_BLOCK = "slot_count"
#: descriptor stamp of a block that is not in the slot's frame
NOT_PUT = -1


def slot_block(slot: int, name: str) -> str:
    """Name of run block ``name`` in slot ``slot``."""
    return f"s{slot}_{name}"


def slot_schema(run: Schema, names: tuple[str, ...], slots: int) -> Schema:
    """Schema of ``slots`` copies of the run's blocks ``names`` (same dtypes, shapes and fields), their
    descriptors and the count of frames put."""
    blocks = [dataclasses.replace(run.block(n), name=slot_block(k, n), writer=SLOT_WRITER)
              for k in range(slots) for n in names]
    blocks += [ArrayBlock(DESCRIPTOR_BLOCK, SLOT_WRITER, "i8", (slots, 1 + len(names))),
               ArrayBlock(COUNT_BLOCK, SLOT_WRITER, "i8", (1,))]
    return Schema(blocks, [SLOT_WRITER])


def block_bytes(view) -> np.ndarray:
    """A block's memory as a flat uint8 array, zero copy (``view``: an ndarray or a StructView of a segment)."""
    arr = view.array if hasattr(view, "array") else view
    return arr.reshape(-1).view(np.uint8)


class FrameSlots:
    """``slots`` frame copies of the run blocks ``names``: the sink creates and fills, the recorder attaches and
    reads. Use as a context manager or call :meth:`close` (and :meth:`unlink`, creator only)."""

    def __init__(self, seg: Segment, names: tuple[str, ...], slots: int):
        self.segment, self.names, self.slots = seg, tuple(names), int(slots)
        self._index = {n: i for i, n in enumerate(self.names)}
        self._structs = {n for n in names if isinstance(seg.schema.block(slot_block(0, n)), StructBlock)}
        #: descriptor rows: [frame of the sink call, stamp of block names[i] at column 1 + i]
        self.descriptors: np.ndarray = seg.view(DESCRIPTOR_BLOCK)
        self._count: np.ndarray = seg.view(COUNT_BLOCK)
        #: per slot, per block: the slot block's bytes (the sink's copy destinations)
        self._dst = [[block_bytes(seg.view(slot_block(k, n))) for n in self.names] for k in range(self.slots)]
        #: the run segment whose block bytes ``_src`` holds (the sink's copy sources, looked up once)
        self._run: Segment | None = None
        self._src: list[np.ndarray] = []

    @classmethod
    def create(cls, run: Schema, names: tuple[str, ...], slots: int) -> "FrameSlots":
        """New slots for ``names`` of schema ``run`` (a uniquely named shared-memory segment)."""
        if slots < 1:
            raise ValueError(f"need at least one frame slot, got {slots}")
        name = f"cosim-{os.getpid()}-rec-{secrets.token_hex(3)}"  # the launcher's pid, like its segment
        made = cls(Segment.create(name, slot_schema(run, names, slots)), names, slots)
        made.descriptors[...] = NOT_PUT
        return made

    @classmethod
    def attach(cls, name: str, run: Schema, names: tuple[str, ...], slots: int) -> "FrameSlots":
        """Attach the slots ``name`` made by :meth:`create` (refuses a layout mismatch)."""
        return cls(Segment.attach(name, expect=slot_schema(run, names, slots)), names, slots)

    @property
    def name(self) -> str:
        return self.segment.name

    # -- the sink's side ---------------------------------------------------------------------------------
    def put(self, run: Segment, slot: int, frame: int, names) -> tuple[str, ...]:
        """Copy run blocks ``names`` (those written at least once) into ``slot`` and describe it: sink call
        ``frame``, each block's own stamp (``run.frame_of``: earlier than ``frame`` for a block that lags).
        Returns the names copied. The caller owns ``slot`` (holds its credit) and counts it afterwards
        (:attr:`count`)."""
        if run is not self._run:
            self._run, self._src = run, [block_bytes(run.view(n)) for n in self.names]
        row = self.descriptors[slot]
        stamps = [NOT_PUT] * len(self.names)
        dst, src, index = self._dst[slot], self._src, self._index
        copied = []
        for n in names:
            stamp = run.frame_of(n)
            if stamp < 0:
                continue
            i = index[n]
            np.copyto(dst[i], src[i])
            stamps[i] = stamp
            copied.append(n)
        row[0] = frame
        row[1:] = stamps
        return tuple(copied)

    @property
    def count(self) -> int:
        """Frames put so far (the sink sets it after each :meth:`put`; the recorder reads it when the launcher
        is gone)."""
        return int(self._count[0])

    @count.setter
    def count(self, n: int) -> None:
        self._count[0] = n

    # -- the recorder's side -----------------------------------------------------------------------------
    def view(self, slot: int, name: str):
        """Zero-copy view of run block ``name`` in ``slot``: an ndarray, or a StructView for struct blocks."""
        return self.segment.view(slot_block(slot, name))

    def stamp(self, slot: int, name: str) -> int:
        """The frame the contents of run block ``name`` in ``slot`` belong to (-1: not in the slot's frame)."""
        return int(self.descriptors[slot, 1 + self._index[name]])

    def frame(self, slot: int) -> tuple[int, FrameData]:
        """(sink call frame, (structs, arrays, stamps)) of ``slot`` for
        :meth:`cosim.recording.writer.McapWriter.write`: the blocks its descriptor lists, struct fields copied
        into dicts, arrays as zero-copy views of the slot (valid until the slot is given back), and each
        block's stamp."""
        row = self.descriptors[slot].tolist()
        structs, arrays, stamps = {}, {}, {}
        for n, stamp in zip(self.names, row[1:]):
            if stamp == NOT_PUT:
                continue
            stamps[n] = stamp
            v = self.view(slot, n)
            if n in self._structs:
                structs[n] = dict(zip(v.array.dtype.names, v.array.item()))
            else:
                arrays[n] = v
        return row[0], FrameData(structs, arrays, stamps)

    def close(self) -> None:
        self._dst, self._src, self._run = [], [], None
        self.descriptors = self._count = None
        self.segment.close()

    def unlink(self) -> None:
        self.segment.unlink()

    def __enter__(self) -> "FrameSlots":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
