"""Per-frame recording, done by the supervisor when it holds the token (so every completed frame is kept).

Every struct-block field becomes a timeseries column ``"<block>.<field>"`` (field names carry their units).
Non-image arrays up to ``ARRAY_COPY_LIMIT`` bytes are copied each frame so the run's final arrays are those of
the last *completed* frame, whatever happens to a writer afterwards. Wall-clock figures are kept apart from the
timeseries, so two runs of the same scenario and seed write byte-identical CSV files.
"""
from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from shm_schema import Segment, StructBlock
from shm_schema.layout import SLOT_WORD

__all__ = ["Recorder", "ARRAY_COPY_LIMIT"]

#: largest array block (bytes) copied every frame for the final outputs
ARRAY_COPY_LIMIT = 4 << 20


class Recorder:
    """Collects struct rows and last-frame array copies from a segment, plus per-stage step times."""

    def __init__(self, seg: Segment, members: tuple[str, ...]):
        self._seg = seg
        self.members = members
        self._structs = [(b.name, seg.view(b.name).array, b) for b in seg.schema.blocks
                         if isinstance(b, StructBlock)]
        self.columns: list[str] = ["frame"] + [f"{name}.{f.name}" for name, _, b in self._structs for f in b.fields]
        self._rows: dict[str, list[np.ndarray]] = {name: [] for name, _, _ in self._structs}
        self.frames: list[int] = []
        self.arrays: dict[str, np.ndarray] = {}
        self._array_views = {}
        for b in seg.schema.blocks:
            if not isinstance(b, StructBlock) and b.kind != "image" and b.nbytes <= ARRAY_COPY_LIMIT:
                self._array_views[b.name] = seg.view(b.name)
                self.arrays[b.name] = np.zeros(b.shape, np.dtype(b.dtype))
        self.array_frames: dict[str, int] = {n: -1 for n in self._array_views}
        self.step_ms: dict[str, list[float]] = {m: [] for m in members}
        self._step_words = [(m, seg.slot_words(m)) for m in members]
        self.turn_ms: list[float] = []

    def record(self, frame: int, turn_ns: int | None = None) -> None:
        """Copy frame ``frame``'s struct rows, small arrays and step times."""
        self.frames.append(frame)
        for name, arr, _ in self._structs:
            self._rows[name].append(arr.copy())
        for name, view in self._array_views.items():
            np.copyto(self.arrays[name], view)
            self.array_frames[name] = self._seg.frame_of(name)
        step = SLOT_WORD["step_ns"]
        for m, words in self._step_words:
            self.step_ms[m].append(words[step] / 1e6)
        if turn_ns is not None:
            self.turn_ms.append(turn_ns / 1e6)

    def series(self) -> dict[str, np.ndarray]:
        """Column name -> (completed frames,) float64 array (the ``frame`` column included)."""
        out = {"frame": np.asarray(self.frames, dtype=np.float64)}
        for name, _, b in self._structs:
            rows = np.array(self._rows[name], dtype=b.dtype) if self._rows[name] else np.zeros(0, b.dtype)
            for f in b.fields:
                out[f"{name}.{f.name}"] = rows[f.name].astype(np.float64)
        return out

    def timing_medians_ms(self) -> dict[str, float]:
        """Median per-frame time of each member's step and of the hand-offs (turn minus steps), ms."""
        out = {m: float(np.median(v)) if v else float("nan") for m, v in self.step_ms.items()}
        if self.turn_ms:
            steps = np.sum([self.step_ms[m][-len(self.turn_ms):] for m in self.members], axis=0)
            out["handoff"] = float(np.median(np.asarray(self.turn_ms) - steps))
        else:
            out["handoff"] = float("nan")
        return out

    def write_csv(self, path: Path) -> None:
        """timeseries.csv: one row per completed frame; floats as shortest round-trip repr (deterministic)."""
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(self.columns)
        cols = []
        for name, _, b in self._structs:
            rows = self._rows[name]
            for f in b.fields:
                cols.append([r[f.name].item() for r in rows])
        for i, frame in enumerate(self.frames):
            w.writerow([frame] + [repr(c[i]) for c in cols])
        Path(path).write_text(buf.getvalue())
