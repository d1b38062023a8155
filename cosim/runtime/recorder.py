"""Per-frame recording, done by the supervisor when it holds the token (so every completed frame is kept).

Every struct-block field becomes a timeseries column ``"<block>.<field>"`` (field names carry their units).
Non-image arrays up to ``FRAME_COPY_LIMIT`` bytes (the height maps, the stream) are copied each frame so the run's
final arrays are those of the last *completed* frame, whatever happens to a writer afterwards. Larger ones (up to
``ARRAY_COPY_LIMIT``: the LiDAR points) are copied once, by :meth:`Recorder.finish`, and only if their seqlock
counter shows no write since the last completed frame (a writer that failed in the next frame leaves them out),
which spares the supervisor a 0.6 MB copy per frame on the ring's critical path. Wall-clock figures are kept
apart from the timeseries: struct fields in ``WALL_CLOCK_UNIT`` (ms; simulated times are in s) go to timing.csv,
the rest to timeseries.csv, so two runs of the same scenario and seed write byte-identical timeseries.csv files.
:meth:`Recorder.csv_rows` formats any range of recorded frames, so the files can be written as the run goes
(cosim.runtime.stream).

A struct row goes to the frame of its block's stamp (``Segment.frame_of``), not to the frame being recorded: a
deferred member (cosim.runtime.participant) publishes frame m's outputs at the next turn, and the flush turn's
:meth:`Recorder.record_flush` adds the last. A frame whose block was not (re)written repeats the block's
latest earlier row, as a block that is not rewritten would read.
"""
from __future__ import annotations

import csv
import io

import numpy as np

from shm_schema import Segment, StructBlock
from shm_schema.layout import SLOT_WORD

__all__ = ["Recorder", "ARRAY_COPY_LIMIT", "FRAME_COPY_LIMIT", "WALL_CLOCK_UNIT"]

#: largest array block (bytes) kept for the final outputs
ARRAY_COPY_LIMIT = 4 << 20
#: largest array block (bytes) copied at every completed frame; larger ones are copied once, at the end
FRAME_COPY_LIMIT = 64 << 10
#: unit of the struct fields that hold wall-clock times (never reproducible): they go to timing.csv
WALL_CLOCK_UNIT = "ms"


class Recorder:
    """Collects struct rows and last-frame array copies from a segment, plus per-stage step times."""

    def __init__(self, seg: Segment, members: tuple[str, ...], *, deferred: bool = False,
                 schedule: str = "sequential"):
        self._seg = seg
        #: names of the segment's blocks
        self.blocks = frozenset(b.name for b in seg.schema.blocks)
        self.members = members
        #: whether a member publishes one turn late: the hand-off time is then not turn minus steps
        self.deferred = deferred
        #: the schedule the run's members took turns by (cosim.runtime.pipeline): "sequential" or "pipelined"
        self.schedule = schedule
        #: (name, the block's bytes as a uint8 view, block): a row is kept as bytes (one memcpy; copying the
        #: structured array field by field cost ~9 us per block per frame)
        self._structs = [(b.name, seg.view(b.name).array.reshape(1).view(np.uint8), b) for b in seg.schema.blocks
                         if isinstance(b, StructBlock)]
        self.columns: list[str] = ["frame"] + [f"{name}.{f.name}" for name, _, b in self._structs for f in b.fields]
        #: the wall-clock columns (timing.csv) and the others (timeseries.csv), "frame" first in both
        self.timing_columns = ["frame"] + [c for c in self.columns[1:] if self._unit(c) == WALL_CLOCK_UNIT]
        self.series_columns = [c for c in self.columns if c not in self.timing_columns[1:]]
        self._rows: dict[str, dict[int, bytes]] = {name: {} for name, _, _ in self._structs}
        self.frames: list[int] = []
        self.arrays: dict[str, np.ndarray] = {}
        self._array_views = {}
        #: arrays copied once by finish(): name -> (seq, frame stamp) at the last completed frame
        self._late: dict[str, tuple[int, int]] = {}
        for b in seg.schema.blocks:
            if not isinstance(b, StructBlock) and b.kind != "image" and b.nbytes <= ARRAY_COPY_LIMIT:
                if b.nbytes <= FRAME_COPY_LIMIT:
                    self._array_views[b.name] = seg.view(b.name)
                else:
                    self._late[b.name] = (-1, -1)
                self.arrays[b.name] = np.zeros(b.shape, np.dtype(b.dtype))
        self.array_frames: dict[str, int] = {n: -1 for n in self.arrays}
        self.step_ms: dict[str, list[float]] = {m: [] for m in members}
        self._step_words = [(m, seg.slot_words(m)) for m in members]
        self._slot_of = dict(self._step_words)
        #: each member's step time (ns) last taken, for the frame being recorded
        self._steps: dict[str, int] = {}
        #: the blocks each member writes (:meth:`take`)
        self._writers = {m: frozenset(b.name for b in seg.schema.blocks if b.writer == m) for m in members}
        self.turn_ms: list[float] = []

    def record(self, frame: int, turn_ns: int | None = None) -> None:
        """Copy frame ``frame``'s struct rows (each to its stamp's frame), small arrays and step times."""
        self._take()
        step = SLOT_WORD["step_ns"]
        for m, words in self._step_words:
            self._steps[m] = words[step]
        self.complete(frame, turn_ns)

    def take(self, writer: str, frame: int) -> None:
        """Copy the blocks of one ``writer`` and its step time, as soon as it has published ``frame`` (the
        pipelined schedule, cosim.runtime.pipeline); :meth:`complete` closes the frame."""
        self._take(writer)
        self._steps[writer] = self._slot_of[writer][SLOT_WORD["step_ns"]]

    def complete(self, frame: int, turn_ns: int | None = None) -> None:
        """Frame ``frame`` is recorded: its step times (each member's last taken) and the turn's."""
        self.frames.append(frame)
        for m, _ in self._step_words:
            self.step_ms[m].append(self._steps.get(m, 0) / 1e6)
        if turn_ns is not None:
            self.turn_ms.append(turn_ns / 1e6)

    def record_flush(self) -> None:
        """After the flush turn: take the rows and arrays the deferred members published last."""
        self._take()

    def finish(self) -> None:
        """Copy the large arrays that are still as they were at the last completed frame (call once the ring has
        stopped, before the segment closes)."""
        seg = self._seg
        for name, (seq, stamp) in self._late.items():
            if stamp >= 0 and seg.seq_of(name) == seq:
                np.copyto(self.arrays[name], seg.view(name))
                self.array_frames[name] = stamp

    def _take(self, writer: str | None = None) -> None:
        """Copy the struct rows and small arrays (and note the large arrays' seqlocks) of every block, or of
        ``writer``'s."""
        seg, mine = self._seg, self._writers.get(writer) if writer is not None else None
        for name, raw, _ in self._structs:
            stamp = seg.frame_of(name)
            if stamp >= 0 and (mine is None or name in mine):
                self._rows[name][stamp] = raw.tobytes()
        for name, view in self._array_views.items():
            if mine is None or name in mine:
                np.copyto(self.arrays[name], view)
                self.array_frames[name] = seg.frame_of(name)
        for name in self._late:
            if mine is None or name in mine:
                self._late[name] = (seg.seq_of(name), seg.frame_of(name))

    def _unit(self, column: str) -> str:
        block, field = column.split(".", 1)
        return next(f.unit for name, _, b in self._structs if name == block for f in b.fields if f.name == field)

    def _aligned(self, name: str, dtype: np.dtype, start: int = 0, stop: int | None = None,
                 carry: dict | None = None) -> np.ndarray:
        """Block ``name``'s row for recorded frames [start, stop): its own, else the latest earlier one (zeros
        before the first), (stop - start,) of the block's structured dtype. ``carry`` (name -> row bytes) holds
        the row in force before ``start`` and is updated, so that consecutive ranges join up."""
        rows, out = self._rows[name], []
        last = (carry or {}).get(name, bytes(dtype.itemsize))
        for f in self.frames[start:stop]:
            last = rows.get(f, last)
            out.append(last)
        if carry is not None:
            carry[name] = last
        return np.frombuffer(b"".join(out), dtype=dtype)

    def series(self) -> dict[str, np.ndarray]:
        """Column name -> (completed frames,) float64 array (the ``frame`` column included), in the order of
        timeseries.csv then timing.csv (as ``cosim.report.load_run`` reads them back)."""
        out = {"frame": np.asarray(self.frames, dtype=np.float64)}
        for name, _, b in self._structs:
            rows = self._aligned(name, b.dtype)
            for f in b.fields:
                out[f"{name}.{f.name}"] = rows[f.name].astype(np.float64)
        return {c: out[c] for c in self.series_columns + self.timing_columns[1:]}

    def timing_medians_ms(self) -> dict[str, float]:
        """Median per-frame time of each member's step, of the whole turn (``frame``) and of the hand-offs
        (turn minus steps; NaN with a deferred member, whose step overlaps the others'), ms."""
        nan = float("nan")
        out = {m: float(np.median(v)) if v else nan for m, v in self.step_ms.items()}
        out["frame"] = float(np.median(self.turn_ms)) if self.turn_ms else nan
        out["handoff"] = nan
        if self.turn_ms and not self.deferred:
            steps = np.sum([self.step_ms[m][-len(self.turn_ms):] for m in self.members], axis=0)
            out["handoff"] = float(np.median(np.asarray(self.turn_ms) - steps))
        return out

    def csv_rows(self, start: int, stop: int, carry: dict) -> tuple[str, str]:
        """(timeseries rows, timing rows) of recorded frames [start, stop) as CSV text; floats as the shortest
        round-trip repr (deterministic). ``carry`` joins consecutive ranges (see :meth:`_aligned`): pass the
        same dict for ranges that follow each other, from 0."""
        cols = {"frame": self.frames[start:stop]}
        for name, _, b in self._structs:
            rows = self._aligned(name, b.dtype, start, stop, carry)
            for f in b.fields:
                cols[f"{name}.{f.name}"] = rows[f.name].tolist()
        out = []
        for names in (self.series_columns, self.timing_columns):
            buf = io.StringIO()
            w = csv.writer(buf, lineterminator="\n")
            picked = [cols[c] for c in names[1:]]
            for i, frame in enumerate(cols["frame"]):
                w.writerow([frame] + [repr(c[i]) for c in picked])
            out.append(buf.getvalue())
        return out[0], out[1]

    @staticmethod
    def csv_header(names: list[str]) -> str:
        return ",".join(names) + "\n"
