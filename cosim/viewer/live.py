"""Attaching to a running co-simulation read-only, by run directory or segment name (docs/architecture.md).

The viewer learns the layout from the segment itself (``Segment.attach`` decodes the stored schema), copies
blocks with the seqlock (``Segment.snapshot``: copy, retry if the writer moved), never writes, never unlinks
(attach does not register with the resource tracker) and takes no part in the lockstep. Snapshots are taken
only when a client asks, at most every ``min_interval_s``; frames in between are dropped. A state snapshot
copies only the struct blocks and reads every block's frame stamp; the big blocks (images, LiDAR, height maps)
are copied only when a panel asks for them (``snapshot(big=True)``), and only if their stamp moved. When the run ends
(the launcher unlinks the segment) the source keeps its last snapshot, reports ``run ended`` and unmaps.
"""
from __future__ import annotations

import json
import logging
import os
import threading
import time
from collections import deque
from pathlib import Path

from shm_schema import Phase, Segment, SegmentNotFound, SnapshotTimeout, StructBlock

from .snapshot import History, Snapshot, wanted_block
from .viewinfo import ViewInfo

__all__ = ["RunNotFound", "RunEnded", "resolve_run", "LiveSource", "SHM_DIR", "MIN_INTERVAL_S", "RECORDING_NAME"]

log = logging.getLogger("cosim.viewer")

SHM_DIR = Path("/dev/shm")
#: shortest time between two snapshots, s (the dashboard polls at about this rate)
MIN_INTERVAL_S = 0.2
#: seqlock attempts per block before a block is skipped for this snapshot (keeps its previous copy)
SNAPSHOT_TRIES = 200
#: window of the real-time factor estimate, s of wall time
RTF_WINDOW_S = 3.0
SUPERVISOR = "supervisor"


class RunNotFound(LookupError):
    """No run of that name: no run directory with a run.json, and no segment of that name."""


class RunEnded(LookupError):
    """The run exists on disk but has ended: its segment is gone."""


#: the file ``launch.py run --record`` writes in the run directory (cosim.recording.writer.DEFAULT_NAME, which
#: imports the Foxglove SDK: not loaded to print a message)
RECORDING_NAME = "recording.mcap"


def _ended_message(run_dir: Path, segment: str) -> str:
    """What to say of a run that has ended: where its outputs are, and how to replay its recording only when one
    was written there (``launch.py run --record``)."""
    text = f"run {run_dir.name} has ended (its segment {segment} is gone); its outputs are in {run_dir}"
    recording = run_dir / RECORDING_NAME
    if recording.is_file() and recording.stat().st_size > 0:
        return f"{text}; replay its recording with `python launch.py replay {recording}`"
    return f"{text} (no recording was written: `launch.py run --record` writes one to replay)"


def resolve_run(run: str | os.PathLike) -> tuple[str, Path | None]:
    """(segment name, run directory or None) of ``run``: a run directory, its run.json, or a segment name.

    Raises :class:`RunEnded` when the run directory says the run has ended, :class:`RunNotFound` when
    ``run`` is a directory without run.json.
    """
    p = Path(run)
    if p.is_file() and p.name == "run.json":
        p = p.parent
    if p.is_dir():
        info_path = p / "run.json"
        if not info_path.is_file():
            raise RunNotFound(f"{p} has no run.json: it is not a run directory, or its run has not started yet")
        try:
            info = json.loads(info_path.read_text())
            segment = str(info["segment"])
        except (ValueError, KeyError, TypeError) as exc:
            raise RunNotFound(f"{info_path} does not name a segment ({type(exc).__name__}: {exc})") from None
        if info.get("ended"):
            raise RunEnded(_ended_message(p, segment))
        return segment, p
    name = str(run)
    if name.startswith(str(SHM_DIR) + "/"):
        name = name[len(str(SHM_DIR)) + 1:]
    if "/" in name:
        raise RunNotFound(f"{run}: no such run directory")
    return name, None


class LiveSource:
    """Snapshots of one running segment. Thread-safe; :meth:`close` unmaps (never unlinks)."""

    def __init__(self, run: str | os.PathLike, min_interval_s: float = MIN_INTERVAL_S):
        self.segment_name, self.run_dir = resolve_run(run)
        try:
            self._seg: Segment | None = Segment.attach(self.segment_name)
        except SegmentNotFound:
            where = f" (run directory {self.run_dir})" if self.run_dir else ""
            raise RunNotFound(f"no running co-simulation with segment {self.segment_name!r}{where}: the run has not "
                              "started, or it has ended") from None
        seg = self._seg
        self.name = seg.run_id or self.segment_name
        self.frames_planned = int(seg.header["frames"])
        self.blocks = [b.name for b in seg.schema.blocks]
        self._wanted = [(b.name, "struct" if isinstance(b, StructBlock) else b.kind,
                         () if isinstance(b, StructBlock) else b.shape) for b in seg.schema.blocks]
        self._kinds = {n: k for n, k, s in self._wanted if wanted_block(n, k, s)}
        self._wanted = list(self._kinds)
        #: big block -> (frame, copy) held for the panels
        self._copies: dict[str, tuple[int, object]] = {}
        self._t_big = -float("inf")
        self._has_sup = SUPERVISOR in seg.schema.participants
        self.min_interval_s = float(min_interval_s)
        self.history = History()
        #: the run's cart, sensors and fill target (cosim.viewer.viewinfo): from the run directory's scenario.yaml
        #: when attached by run directory, else set by whoever knows the scenario (None: unknown)
        self.view: ViewInfo | None = ViewInfo.from_scenario_yaml(self.run_dir / "scenario.yaml") \
            if self.run_dir else None
        #: the cart interior's (length, width), m (the height maps' metre axes)
        self.size_m = self.view.size_m if self.view is not None else None
        self._lock = threading.Lock()
        self._last = Snapshot(status="attached")
        self._t_last = -float("inf")
        self._rtf: deque = deque()
        self._ended = False
        self.samples = 0

    # -- state -------------------------------------------------------------------------------------------
    @property
    def ended(self) -> bool:
        return self._ended

    def _alive(self) -> bool:
        if SHM_DIR.is_dir():
            return (SHM_DIR / self.segment_name).exists()
        return True

    def finish(self) -> None:
        """The run has ended (its launcher is stopping the viewer): keep the segment's last frame as the final
        snapshot, status ``run ended``, and unmap."""
        with self._lock:
            if not self._ended:
                self._end()

    def check_end(self) -> bool:
        """Notice a run that has ended: keep the last snapshot, unmap. Returns whether it has ended."""
        with self._lock:
            if not self._ended and not self._alive():
                self._end()
            return self._ended

    def _end(self) -> None:
        """The name is gone but the mapping still holds the run's final state: copy it once, then unmap."""
        self._ended = True
        if self._seg is not None:
            try:
                self._last = self._take(self._seg, self._last, big=True)
                self.history.add(self._last)
            except Exception:  # noqa: BLE001 - keep the previous snapshot
                log.exception("viewer: final snapshot of %s failed", self.name)
        self._last.status = "run ended"
        self._last.rtf = None
        if self._seg is not None:
            self._seg.close()
            self._seg = None
        log.info("viewer: run %s ended; showing its last frame %d", self.name, self._last.frame)

    def snapshot(self, big: bool = False) -> Snapshot:
        """The latest snapshot, taking a new one if the last is older than ``min_interval_s``.

        ``big``: also bring the copies of the big blocks up to date (what the image panels draw).
        """
        with self._lock:
            now = time.monotonic()
            if self._ended:
                return self._last
            fresh = now - self._t_last < self.min_interval_s
            if fresh and (not big or now - self._t_big < self.min_interval_s):
                return self._last
            if not self._alive():
                self._end()
                return self._last
            if not fresh:
                self._t_last = now
                self.samples += 1
            if big:
                self._t_big = now
            self._last = self._take(self._seg, self._last, big)
            self.history.add(self._last)
            return self._last

    def _take(self, seg: Segment, prev: Snapshot, big: bool = False) -> Snapshot:
        snap = Snapshot()
        for name in self._wanted:
            kind = self._kinds[name]
            snap.stamps[name] = seg.frame_of(name)
            if kind != "struct":
                held = self._copies.get(name)
                if big and (held is None or held[0] != snap.stamps[name]) and snap.stamps[name] >= 0:
                    try:
                        self._copies[name] = held = seg.snapshot(name, tries=SNAPSHOT_TRIES)
                    except SnapshotTimeout:
                        pass  # the writer kept writing: keep the copy held
                if held is not None:
                    snap.frames[name] = held[0]
                    (snap.images if kind == "image" else snap.arrays)[name] = held[1]
                continue
            try:
                frame, data = seg.snapshot(name, tries=SNAPSHOT_TRIES)
            except SnapshotTimeout:
                if name not in prev.structs:
                    continue
                frame, data = prev.frames[name], prev.structs[name]
            snap.frames[name] = frame
            snap.structs[name] = data
        if self._has_sup:
            slot = seg.slot(SUPERVISOR)
            snap.frame = int(slot["frame"])
            phase = int(slot["phase"])
            beat = int(slot["heartbeat_ns"]) or time.monotonic_ns()
        else:
            snap.frame = max([f for f in snap.frames.values()], default=-1)
            phase, beat = Phase.STEPPING, time.monotonic_ns()
        snap.status = "finished" if phase == Phase.DONE else "running" if snap.frame >= 0 else "starting"
        snap.dropped = max(0, snap.frame - prev.frame - 1) if prev.frame >= 0 else 0
        snap.rtf = self._rtf_update(beat, snap.t_s)
        return snap

    def _rtf_update(self, beat_ns: int, t_s: float | None) -> float | None:
        if t_s is None:
            return None
        if self._rtf and self._rtf[-1][1] == t_s:
            beat_ns = self._rtf[-1][0]
        else:
            self._rtf.append((beat_ns, t_s))
        while len(self._rtf) > 2 and (beat_ns - self._rtf[0][0]) / 1e9 > RTF_WINDOW_S:
            self._rtf.popleft()
        (b0, t0), (b1, t1) = self._rtf[0], self._rtf[-1]
        return (t1 - t0) / ((b1 - b0) / 1e9) if b1 > b0 and t1 > t0 else None

    def close(self) -> None:
        """Unmap the segment (never unlinks it). Idempotent."""
        with self._lock:
            if self._seg is not None:
                self._seg.close()
                self._seg = None

    def __enter__(self) -> "LiveSource":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
