"""Frame slots: a small shared-memory ring through which the sink hands whole frames to the recorder process.

The sink (in the supervisor, while it holds the token) copies the recorded blocks of a completed frame into
slot ``k`` (one memcpy per block, no pickling; each slot block keeps its run block's stamp, the frame its
contents belong to) and sends the recorder a few bytes: ``(frame, k, blocks copied)``. The recorder encodes
straight from the slot's named views and gives the slot back (a credit) when
it is done with it. The slots are a :class:`shm_schema.Segment` of their own: slot ``k`` of run block ``b`` is
block ``s<k>_<b>``, so layout, named views, attach with fingerprint check and the creator-only unlink all come
from ``shm_schema``; nothing here computes an offset.
"""
from __future__ import annotations

import dataclasses
import os
import secrets

import numpy as np

from shm_schema import Schema, Segment, StructBlock

from .writer import FrameData

__all__ = ["FrameSlots", "SLOT_WRITER", "slot_schema", "slot_block"]

#: the (only) writer of the slot segment's blocks: the recording sink
SLOT_WRITER = "sink"


def slot_block(slot: int, name: str) -> str:
    """Name of run block ``name`` in slot ``slot``."""
    return f"s{slot}_{name}"


def slot_schema(run: Schema, names: tuple[str, ...], slots: int) -> Schema:
    """Schema of ``slots`` copies of the run's blocks ``names`` (same dtypes, shapes and fields)."""
    blocks = [dataclasses.replace(run.block(n), name=slot_block(k, n), writer=SLOT_WRITER)
              for k in range(slots) for n in names]
    return Schema(blocks, [SLOT_WRITER])


class FrameSlots:
    """``slots`` frame copies of the run blocks ``names``: the sink creates and fills, the recorder attaches and
    reads. Use as a context manager or call :meth:`close` (and :meth:`unlink`, creator only)."""

    def __init__(self, seg: Segment, names: tuple[str, ...], slots: int):
        self.segment, self.names, self.slots = seg, tuple(names), int(slots)
        self._structs = {n for n in names if isinstance(seg.schema.block(slot_block(0, n)), StructBlock)}

    @classmethod
    def create(cls, run: Schema, names: tuple[str, ...], slots: int) -> "FrameSlots":
        """New slots for ``names`` of schema ``run`` (a uniquely named shared-memory segment)."""
        if slots < 1:
            raise ValueError(f"need at least one frame slot, got {slots}")
        name = f"cosim-{os.getpid()}-rec-{secrets.token_hex(3)}"  # the launcher's pid, like its segment
        return cls(Segment.create(name, slot_schema(run, names, slots)), names, slots)

    @classmethod
    def attach(cls, name: str, run: Schema, names: tuple[str, ...], slots: int) -> "FrameSlots":
        """Attach the slots ``name`` made by :meth:`create` (refuses a layout mismatch)."""
        return cls(Segment.attach(name, expect=slot_schema(run, names, slots)), names, slots)

    @property
    def name(self) -> str:
        return self.segment.name

    def put(self, run: Segment, slot: int, frame: int, names) -> tuple[str, ...]:
        """Copy run blocks ``names`` (those written at least once) into ``slot``, each with its own stamp (the
        frame its contents belong to, ``run.frame_of``: earlier than ``frame``, the sink call's, for a block
        that lags); returns the names copied."""
        copied = []
        for n in names:
            stamp = run.frame_of(n)
            if stamp < 0:
                continue
            src = run.view(n)
            with self.segment.write(slot_block(slot, n), stamp) as dst:
                if n in self._structs:
                    dst.array[...] = src.array
                else:
                    np.copyto(dst, src)
            copied.append(n)
        return tuple(copied)

    def view(self, slot: int, name: str):
        """Zero-copy view of run block ``name`` in ``slot``: an ndarray, or a StructView for struct blocks."""
        return self.segment.view(slot_block(slot, name))

    def stamp(self, slot: int, name: str) -> int:
        """The frame the contents of run block ``name`` in ``slot`` belong to (-1: never put)."""
        return self.segment.frame_of(slot_block(slot, name))

    def frame(self, slot: int, names) -> FrameData:
        """(structs, arrays, stamps) of the run blocks ``names`` in ``slot`` for
        :meth:`cosim.recording.writer.McapWriter.write`: struct fields copied into dicts, arrays as zero-copy
        views of the slot (valid until the slot is given back), and each block's stamp."""
        structs, arrays, stamps = {}, {}, {}
        for n in names:
            v = self.view(slot, n)
            stamps[n] = self.stamp(slot, n)
            if n in self._structs:
                structs[n] = dict(zip(v.array.dtype.names, v.array.item()))
            else:
                arrays[n] = v
        return FrameData(structs, arrays, stamps)

    def close(self) -> None:
        self.segment.close()

    def unlink(self) -> None:
        self.segment.unlink()

    def __enter__(self) -> "FrameSlots":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
