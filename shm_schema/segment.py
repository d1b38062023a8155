"""One run's shared-memory segment: create (launcher), attach (children, viewers), local (in-process).

The segment is self-describing: a reader needs only its name. ``attach`` checks the magic, the layout version
and the fingerprint, and refuses a mismatch with :class:`SchemaMismatch` naming both sides. Only the creator
unlinks; attachers ``close``. On Python < 3.13 attaching would register the segment with the attaching
process's resource tracker, which then deletes it when that process exits; attach therefore never registers.
"""
from __future__ import annotations

import struct
import sys
import threading
import time
from multiprocessing import resource_tracker, shared_memory

import msgpack
import numpy as np

from .layout import BLOCK_HEADER_DTYPE, BLOCK_WORD, ERROR_BYTES, HEADER_DTYPE, LAYOUT_VERSION, MAGIC, PROC_DTYPE, Schema
from .spec import StructBlock

__all__ = ["Segment", "StructView", "BlockWrite", "SchemaMismatch", "SegmentNotFound", "Phase", "SnapshotTimeout"]

_SEQ, _FRAME, _T_NS = BLOCK_WORD["seq"], BLOCK_WORD["frame"], BLOCK_WORD["t_ns"]


class SchemaMismatch(RuntimeError):
    """The segment's layout is not the one the attaching process expects."""


class SegmentNotFound(FileNotFoundError):
    """No segment of that name exists (the run has not started, or has ended)."""


class SnapshotTimeout(RuntimeError):
    """An observer could not take a consistent copy of a block (its writer kept writing or failed mid-write)."""


class Phase:
    """Values of a process slot's ``phase`` (what the process is doing now)."""

    IDLE, STARTING, WAITING, STEPPING, DONE, FAILED, CLOSED = range(7)
    NAMES = ("idle", "starting", "waiting", "stepping", "done", "failed", "closed")


_REGISTER_LOCK = threading.Lock()


def _attach_untracked(name: str) -> shared_memory.SharedMemory:
    """Open an existing segment without registering it with this process's resource tracker."""
    if sys.version_info >= (3, 13):
        return shared_memory.SharedMemory(name=name, create=False, track=False)
    with _REGISTER_LOCK:
        original = resource_tracker.register
        resource_tracker.register = lambda *args, **kwargs: None
        try:
            return shared_memory.SharedMemory(name=name, create=False)
        finally:
            resource_tracker.register = original


#: struct-module codes of the field types that :meth:`StructView.assign` packs in one call (little-endian)
_PACK_CODES = {"<f8": "d", "<i8": "q"}


class StructView:
    """Attribute access to a struct block's fields, zero copy: ``v.t_s``, ``v.t_s = 1.0``."""

    __slots__ = ("_arr", "_names", "_packer", "_raw")

    def __init__(self, arr: np.ndarray):
        object.__setattr__(self, "_arr", arr)
        object.__setattr__(self, "_names", frozenset(arr.dtype.names))
        codes = [_PACK_CODES.get(arr.dtype.fields[n][0].str) for n in arr.dtype.names]
        packed = all(codes) and struct.calcsize("<" + "".join(codes)) == arr.dtype.itemsize
        object.__setattr__(self, "_packer", struct.Struct("<" + "".join(codes)) if packed else None)
        object.__setattr__(self, "_raw", arr.reshape(1).view(np.uint8))

    def assign(self, values) -> None:
        """Write every field at once, in declaration order (a sequence of as many values). A record of float64
        and int64 fields is packed in one call (integer fields then need ints, not floats); ~1 us against ~15 us
        for assigning a tuple to the structured array."""
        if self._packer is not None:
            self._packer.pack_into(self._raw, 0, *values)
        else:
            self._arr[()] = tuple(values)

    def __getattr__(self, name: str):
        if name not in self._names:
            raise AttributeError(f"struct has no field {name!r}; fields: {sorted(self._names)}")
        return self._arr[name].item()

    def __setattr__(self, name: str, value) -> None:
        if name not in self._names:
            raise AttributeError(f"struct has no field {name!r}; fields: {sorted(self._names)}")
        self._arr[name] = value

    @property
    def array(self) -> np.ndarray:
        """The underlying 0-d structured array (zero copy)."""
        return self._arr

    def as_dict(self) -> dict[str, float | int]:
        """A plain copy of every field."""
        rec = self._arr.copy()
        return {n: rec[n].item() for n in self._arr.dtype.names}

    def update(self, values: dict) -> None:
        for k, v in values.items():
            setattr(self, k, v)


class BlockWrite:
    """Context manager of one write of a block (:meth:`Segment.write`): seq odd on entry; on a clean exit the
    frame and time stamps, then seq even again. A plain class: a generator-based context manager costs ~2 us
    more per write, paid by every writer for every block of every frame."""

    __slots__ = ("_words", "_view", "_frame")

    def __init__(self, words: memoryview, view, frame: int):
        self._words, self._view, self._frame = words, view, frame

    def __enter__(self):
        self._words[_SEQ] += 1
        return self._view

    def __exit__(self, exc_type, exc, tb) -> bool:
        w = self._words
        if exc_type is None:
            w[_FRAME] = self._frame
            w[_T_NS] = time.monotonic_ns()
        w[_SEQ] += 1
        return False


class Segment:
    """Named zero-copy views over one run's blocks, plus the header's process slots."""

    def __init__(self, buf, schema: Schema, shm: shared_memory.SharedMemory | None, owner: bool):
        self.schema = schema
        self._shm = shm
        self._owner = owner
        self._buf = buf
        self.header = np.ndarray((), HEADER_DTYPE, buffer=buf, offset=0)
        #: called with no arguments before every :meth:`write` while set: the pipelined schedule
        #: (cosim.runtime.pipeline) holds a member's first write of a frame until its readers have read the last
        self.write_gate = None
        self._views: dict[str, object] = {}
        self._words: list[memoryview] = []
        #: each block header as int64 words [seq, frame, t_ns] (BLOCK_WORD): a word store is ~10x cheaper than a
        #: structured field's, and every writer touches three per block per frame
        self._bwords: dict[str, memoryview] = {}
        raw = memoryview(buf).cast("B")
        self._words.append(raw)
        for name, lay in schema.layout.items():
            words = raw[lay.offset:lay.offset + BLOCK_HEADER_DTYPE.itemsize].cast("q")
            self._words.append(words)
            self._bwords[name] = words
            b = lay.block
            if isinstance(b, StructBlock):
                self._views[name] = StructView(np.ndarray((), b.dtype, buffer=buf, offset=lay.data_offset))
            else:
                self._views[name] = np.ndarray(b.shape, np.dtype(b.dtype), buffer=buf, offset=lay.data_offset)

    # -- construction ------------------------------------------------------------------------------------
    @staticmethod
    def _init_header(buf, schema: Schema, run_id: str, frames: int) -> None:
        hdr = np.ndarray((), HEADER_DTYPE, buffer=buf, offset=0)
        hdr["magic"] = MAGIC
        hdr["layout_version"] = LAYOUT_VERSION
        hdr["n_procs"] = len(schema.participants)
        hdr["fingerprint"] = schema.fingerprint.encode()
        hdr["run_id"] = run_id.encode()[:32]
        hdr["schema_offset"] = schema.schema_offset
        hdr["schema_nbytes"] = len(schema.encoded)
        hdr["total_nbytes"] = schema.total_nbytes
        hdr["frames"] = frames
        for i, p in enumerate(schema.participants):
            hdr["procs"][i]["name"] = p.encode()
            hdr["procs"][i]["frame"] = -1
            hdr["procs"][i]["token"] = -1
        raw = np.frombuffer(buf, np.uint8, len(schema.encoded), schema.schema_offset)
        raw[:] = np.frombuffer(schema.encoded, np.uint8)
        for lay in schema.layout.values():
            bh = np.ndarray((), BLOCK_HEADER_DTYPE, buffer=buf, offset=lay.offset)
            bh["frame"] = -1

    @classmethod
    def create(cls, name: str, schema: Schema, run_id: str = "", frames: int = 0) -> "Segment":
        """Create and initialise the named segment. The caller owns it and must :meth:`unlink` it."""
        shm = shared_memory.SharedMemory(name=name, create=True, size=schema.total_nbytes)
        try:
            cls._init_header(shm.buf, schema, run_id, frames)
        except BaseException:
            shm.close()
            shm.unlink()
            raise
        return cls(shm.buf, schema, shm, owner=True)

    @classmethod
    def local(cls, schema: Schema, run_id: str = "local", frames: int = 0) -> "Segment":
        """An in-process segment over ordinary memory (tests, debugging, the in-process ring)."""
        buf = bytearray(schema.total_nbytes)
        cls._init_header(buf, schema, run_id, frames)
        return cls(memoryview(buf), schema, None, owner=False)

    @classmethod
    def attach(cls, name: str, expect: Schema | str | None = None) -> "Segment":
        """Attach to a running segment by name, learning its layout from the segment itself.

        ``expect`` (a Schema or a fingerprint) makes attach refuse any other layout with :class:`SchemaMismatch`.
        """
        try:
            shm = _attach_untracked(name)
        except FileNotFoundError:
            raise SegmentNotFound(f"no run segment named {name!r} (not started yet, or already ended)") from None
        try:
            hdr = np.ndarray((), HEADER_DTYPE, buffer=shm.buf, offset=0)
            if shm.size < HEADER_DTYPE.itemsize or hdr["magic"].item() != MAGIC:
                raise SchemaMismatch(f"segment {name!r} is not a co-simulation segment (bad magic)")
            version = int(hdr["layout_version"])
            if version != LAYOUT_VERSION:
                raise SchemaMismatch(
                    f"segment {name!r} has layout version {version}, this process expects {LAYOUT_VERSION}")
            stored = hdr["fingerprint"].item().decode()
            want = expect.fingerprint if isinstance(expect, Schema) else expect
            if want is not None and stored != want:
                raise SchemaMismatch(
                    f"segment {name!r} has schema fingerprint {stored}, but this process expects {want}: the "
                    "writer and reader were built from different scenarios or code versions; restart both from "
                    "the same scenario")
            off, n = int(hdr["schema_offset"]), int(hdr["schema_nbytes"])
            schema = Schema.decode(bytes(shm.buf[off:off + n]))
            if schema.fingerprint != stored:
                raise SchemaMismatch(f"segment {name!r}: stored schema does not hash to its fingerprint {stored}")
            del hdr
            return cls(shm.buf, schema, shm, owner=False)
        except BaseException:
            shm.close()
            raise

    # -- blocks ------------------------------------------------------------------------------------------
    def has(self, name: str) -> bool:
        """Whether this run allocated block ``name``."""
        return name in self._views

    def view(self, name: str):
        """Zero-copy view of a block: an ndarray, or a :class:`StructView` for struct blocks."""
        try:
            return self._views[name]
        except KeyError:
            raise KeyError(f"no block {name!r} in this run; blocks: {sorted(self._views)}") from None

    def write(self, name: str, frame: int) -> "BlockWrite":
        """``with seg.write(name, frame) as view:`` writes block ``name`` for ``frame`` under its seqlock (odd
        while writing), then stamps the frame; a write that raises leaves the stamp as it was. The
        :attr:`write_gate`, when set, runs first."""
        if self.write_gate is not None:
            self.write_gate()
        return BlockWrite(self._bwords[name], self._views[name], frame)

    def frame_of(self, name: str) -> int:
        """Frame stamp of the last completed write of ``name`` (-1 before any)."""
        return self._bwords[name][_FRAME]

    def seq_of(self, name: str) -> int:
        """Seqlock counter of ``name``: odd while a write is in progress, +2 per completed write."""
        return self._bwords[name][_SEQ]

    def snapshot(self, name: str, tries: int = 1000):
        """(frame, copy) of block ``name``, consistent under its seqlock; never blocks the writer.

        For struct blocks the copy is a dict. Raises :class:`SnapshotTimeout` after ``tries`` failed attempts.
        """
        bw = self._bwords[name]
        v = self._views[name]
        for attempt in range(tries):
            s1 = bw[_SEQ]
            if s1 % 2 == 0:
                data = v.as_dict() if isinstance(v, StructView) else np.array(v, copy=True)
                frame = bw[_FRAME]
                if bw[_SEQ] == s1:
                    return frame, data
            if attempt > 8:
                time.sleep(50e-6)
        raise SnapshotTimeout(f"block {name!r} kept changing during {tries} attempts to copy it")

    # -- process slots -----------------------------------------------------------------------------------
    def slot(self, process: str) -> np.ndarray:
        """The header slot (0-d structured view) of ``process``."""
        try:
            i = self.schema.participants.index(process)
        except ValueError:
            raise KeyError(f"no process slot {process!r}; slots: {self.schema.participants}") from None
        return self.header["procs"][i]

    def slot_words(self, process: str) -> memoryview:
        """``process``'s slot as int64 words (a cast memoryview, zero copy), indexed by ``layout.SLOT_WORD``.

        The lockstep's hot path uses this: a word store costs ~0.1 us against ~1.2 us for a structured field.
        """
        i = self.schema.participants.index(process)
        off = HEADER_DTYPE.fields["procs"][1] + i * PROC_DTYPE.itemsize
        words = memoryview(self._buf)[off:off + PROC_DTYPE.itemsize - ERROR_BYTES].cast("B").cast("q")
        self._words.append(words)
        return words

    def report_error(self, process: str, frame: int, kind: str, message: str, traceback: str) -> None:
        """Store an error report in ``process``'s slot (truncated to fit)."""
        payload = {"process": process, "frame": frame, "type": kind, "message": message[:2000],
                   "traceback": traceback}
        raw = msgpack.packb(payload, use_bin_type=True)
        while len(raw) > ERROR_BYTES and payload["traceback"]:
            payload["traceback"] = "...\n" + payload["traceback"][len(payload["traceback"]) // 2:]
            raw = msgpack.packb(payload, use_bin_type=True)
        slot = self.slot(process)
        slot["error"] = raw[:ERROR_BYTES]
        slot["error_len"] = len(raw)

    def read_error(self, process: str) -> dict | None:
        """The error report of ``process``, or None."""
        slot = self.slot(process)
        n = int(slot["error_len"])
        if n <= 0:
            return None
        return msgpack.unpackb(slot["error"].tobytes()[:n], raw=False)

    @property
    def run_id(self) -> str:
        return self.header["run_id"].item().decode()

    @property
    def fingerprint(self) -> str:
        return self.header["fingerprint"].item().decode()

    # -- lifetime ----------------------------------------------------------------------------------------
    @property
    def name(self) -> str | None:
        return self._shm.name if self._shm is not None else None

    def close(self) -> None:
        """Drop every view and unmap (attachers and owner alike). Idempotent."""
        self._views.clear()
        self._bwords.clear()
        for w in reversed(self._words):
            w.release()
        self._words.clear()
        self.header = None
        self._buf = None
        if self._shm is not None:
            try:
                self._shm.close()
            except BufferError:
                # a caller still holds a view; the mapping goes with the process
                pass

    def unlink(self) -> None:
        """Remove the segment name (creator only)."""
        if not self._owner:
            raise PermissionError("only the process that created a segment may unlink it")
        if self._shm is not None:
            try:
                self._shm.unlink()
            except FileNotFoundError:
                pass

    def __enter__(self) -> "Segment":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
        if self._owner:
            self.unlink()
