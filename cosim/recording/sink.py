"""The recording sink of the launcher (``launch(..., sinks=[mcap_sink()])``) and its recorder process.

The supervisor calls the sink after each completed frame while it holds the token, so it sees every frame
consistently. The sink only copies the frame's recorded blocks into a free frame slot (:mod:`.slots`, shared
memory: one memcpy per block, nothing pickled); the recorder (spawned, nice 10) builds the messages and writes
them from the slot (:class:`~cosim.recording.writer.McapWriter`), then gives the slot back. At most
``queue_frames`` frames are in flight (a semaphore of credits, one per slot; by default as many slots as fit in
QUEUE_BYTES): when the recorder cannot keep up the sink waits, so a recording never loses a frame.

Wake-ups are batched: the sink tells the recorder the count of frames put (an 8-byte message) only every
NOTIFY_FRAMES frames or NOTIFY_S seconds, and always before it would wait for a credit. A ground-truth run of
~1 ms frames so wakes the recorder ~30 times a second instead of ~1000 (each wake-up is scheduler work on both
sides, and lands the recorder on the core the next ring member is about to be woken on). ``queue_frames=0``
writes synchronously inside the sink, with no process.

Ends: ``close`` (end of run, failure, stop) sends the count and the end mark and waits for the recorder to write
every frame put and finish the file. If the launcher itself is killed, the recorder sees the pipe close, takes
every frame counted in the slots' shared count (told of or not: the batching loses nothing; its mapping of the
slots outlives their name) and finishes the file. A recording failure (disk full, a dead, stopped or stalled
recorder) is logged once, in one line, the recorder is ended (SIGTERM, then SIGKILL) and recording stops; the
run goes on. A recorder that is only slow (a busy machine; it runs at a lower priority) holds the ring back
through the credits, however long, so the recording stays whole; one that makes no progress (stopped, or its
threads without CPU time for RECORDER_IDLE_S while it has frames to write: cosim.runtime.liveness.Evidence) is
given up on, by the sink and by ``close`` alike: an observer that has stopped can never hold the run.
"""
from __future__ import annotations

import logging
import multiprocessing as mp
import os
import struct
import time
from pathlib import Path

from cosim.errors import RecordingFailed
from cosim.runtime.files import write_error
from cosim.runtime.liveness import CONFIRM_S, IDLE_S, Evidence, end_process, is_stopped
from cosim.runtime.spawning import start_process
from shm_schema import Schema, Segment

from .slots import FrameSlots
from .writer import (
    DEFAULT_NAME,
    McapWriter,
    Recorded,
    RecordOptions,
    RunInfo,
    frame_data,
)

__all__ = ["McapRecorder", "mcap_sink", "slot_count", "CREDIT_POLL_S", "CLOSE_CPU_S", "RECORDER_IDLE_S", "QUEUE_BYTES",
           "MIN_SLOTS",
           "MAX_SLOTS", "NOTIFY_FRAMES", "NOTIFY_S", "RELEASE_FRAMES"]

log = logging.getLogger("cosim.recording")

#: slice of the sink's wait for a credit, s: bounds how late a dead or stopped recorder is noticed
CREDIT_POLL_S = 0.1
#: CPU time the recorder may spend finishing after ``close`` (writing what it was sent), s of its CPU time
CLOSE_CPU_S = 120.0
#: a recorder with frames to write whose threads use no CPU time and wait for no core or disk for this long is
#: ended (by the sink or ``close``), s
RECORDER_IDLE_S = 2 * IDLE_S
#: grace between SIGTERM and SIGKILL when ending the recorder, s
END_GRACE_S = 1.0
#: exit status of a recorder that stopped on a write error (it printed the error in one line)
EXIT_WRITE_FAILED = 3
#: shared memory for frame slots when ``queue_frames`` is None, bytes: many slots absorb the recorder's
#: scheduling delays (it runs at a lower priority than the ring) without holding up the ring
QUEUE_BYTES = 64 * 2**20
#: fewest and most frame slots when sized by QUEUE_BYTES
MIN_SLOTS, MAX_SLOTS = 4, 256
#: the sink tells the recorder of new frames at least every this many frames (at most half the slots)...
NOTIFY_FRAMES = 32
#: ...and at least this often, s, while frames keep coming: a frame reaches the recorder at most this late
#: (plus one frame), and the file at most ``RecordOptions.flush_s`` after that
NOTIFY_S = 0.03
#: the recorder gives slots back (credits) in batches of this many frames (at most a quarter of the slots), and
#: all it holds whenever it has caught up: a sink that had to wait then wakes once per batch, not once per frame
RELEASE_FRAMES = 8
#: a notification: the count of frames put so far (int64); the end mark is an empty message
_COUNT = struct.Struct("<q")


def slot_count(options: RecordOptions, frame_bytes: int) -> int:
    """Frame slots for frames of ``frame_bytes`` (0: record synchronously, no recorder process)."""
    if options.queue_frames is not None:
        return options.queue_frames
    return max(MIN_SLOTS, min(MAX_SLOTS, QUEUE_BYTES // max(1, frame_bytes)))


def _recorder_main(conn, credits, run: RunInfo, schema_bytes: bytes, slots_name: str, n_slots: int, path: str,
                   options: RecordOptions, run_id: str, fingerprint: str) -> None:
    """Recorder process: :func:`_record`; a write error (a full disk) ends it with one line on stderr, no
    traceback, and exit status EXIT_WRITE_FAILED."""
    import signal
    import sys

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the launcher handles Ctrl-C and then closes us
    try:
        _record(conn, credits, run, schema_bytes, slots_name, n_slots, path, options, run_id, fingerprint)
    except OSError as exc:
        sys.stderr.write(f"recording stopped: {write_error(exc, path)}\n")
        sys.stderr.flush()
        os._exit(EXIT_WRITE_FAILED)


def _record(conn, credits, run: RunInfo, schema_bytes: bytes, slots_name: str, n_slots: int, path: str,
            options: RecordOptions, run_id: str, fingerprint: str) -> None:
    """Encode and write each frame put, in order, from its slot, and give the slot back; flush whenever
    ``flush_s`` has passed since the last flush (busy or idle), so a frame is on disk at most that late after the
    recorder heard of it."""
    schema = Schema.decode(schema_bytes)
    writer = McapWriter(run, schema, Path(path), options, run_id, fingerprint, flush_s=options.flush_s)
    slots = FrameSlots.attach(slots_name, schema, Recorded.of(schema).names, n_slots)
    cpu0 = time.process_time()  # start-up (interpreter, imports, writer, slots) ends here
    release_every = max(1, min(RELEASE_FRAMES, n_slots // 4))
    done = wakeups = held = 0
    try:
        end = False
        while not end:
            # the pipe holds small messages, at most one per slot, so it never needs draining ahead
            if not conn.poll(writer.flush_due_in()):
                writer.flush()
                continue
            wakeups += 1
            try:
                msg = conn.recv_bytes()
            except (EOFError, OSError):  # the launcher is gone: take every frame it finished putting
                upto, end = slots.count, True
            else:
                end = not msg
                upto = done if end else _COUNT.unpack(msg)[0]
            while done < upto:
                frame, data = slots.frame(done % n_slots)
                writer.write(frame, *data)
                done += 1
                held += 1
                if held >= release_every:
                    held = _give_back(credits, held)
            held = _give_back(credits, held)  # caught up: every slot back before waiting for more
    finally:
        # what recording cost: this process's CPU time since it was ready (encode, compress, write), s
        writer.close({"process_cpu_s": repr(time.process_time() - cpu0), "startup_cpu_s": repr(cpu0),
                      "wakeups": str(wakeups)})
        slots.close()


def _give_back(credits, n: int) -> int:
    """Give ``n`` slots back to the sink; returns the number still held (0)."""
    for _ in range(n):
        credits.release()
    return 0


class RecorderGone(RuntimeError):
    """The recorder process cannot take more frames (ended, stopped, stalled)."""


class McapRecorder:
    """The per-frame sink: copy into a frame slot in the supervisor, encode and write in the recorder process."""

    def __init__(self, scenario, run_dir: Path, segment: Segment, options: RecordOptions | None = None):
        self.options = options or RecordOptions()
        self.path = Path(self.options.path) if self.options.path else Path(run_dir) / DEFAULT_NAME
        self.recorded = Recorded.of(segment.schema)
        self._failed = False
        #: why the recording is not whole, and the frame it stopped at (see :attr:`error`)
        self._problem: tuple[str, int] | None = None
        self._last_frame = -1
        self._closed = False
        self._writer: McapWriter | None = None
        self._proc = None
        self._slots: FrameSlots | None = None
        #: frames put into slots, and the count last told to the recorder (when)
        self._sent = self._told = 0
        self._t_told = time.monotonic()
        #: per block, the newest stamp handed to the writer
        self._stamps: dict[str, int] = {}
        #: times the sink found every slot full and the ring waited for the recorder, and how long in all, s
        self.waits, self.wait_s = 0, 0.0
        #: when the recorder was first seen stopped while the sink waited (time.monotonic(), s), 0 when not
        self._stopped_at = 0.0
        n_slots = slot_count(self.options, sum(segment.schema.block(n).nbytes for n in self.recorded.names))
        if n_slots == 0:
            self._writer = McapWriter(scenario, segment.schema, self.path, self.options, segment.run_id,
                                      segment.fingerprint)
            return
        ctx = mp.get_context("spawn")
        self._slots = FrameSlots.create(segment.schema, self.recorded.names, n_slots)
        self._notify_frames = max(1, min(NOTIFY_FRAMES, n_slots // 2))
        self._credits = ctx.Semaphore(n_slots)
        recv, self._conn = ctx.Pipe(duplex=False)
        try:
            self._proc = start_process(_recorder_main, (recv, self._credits, RunInfo.of(scenario),
                                                        segment.schema.encoded, self._slots.name, n_slots,
                                                        str(self.path), self.options, segment.run_id,
                                                        segment.fingerprint), name="cosim-recorder")
        except BaseException:
            self._release_slots()
            raise
        recv.close()
        if self.options.nice:  # from its start: its imports then yield to the ring's children starting up too
            try:
                os.setpriority(os.PRIO_PROCESS, self._proc.pid, os.getpriority(os.PRIO_PROCESS, 0) + self.options.nice)
            except OSError as exc:
                log.warning("could not lower the recorder's priority: %s", exc)

    def __call__(self, seg: Segment, frame: int) -> None:
        """Record completed frame ``frame`` (called by the supervisor while it holds the token): the due blocks
        whose stamp (``seg.frame_of``) is newer than the one last recorded, each at its own stamp. A block may
        lag ``frame`` (perception one frame behind); a last call with ``frame`` = last frame + 1 then records
        just the lagging blocks."""
        if self._failed or self._closed:
            return
        self._last_frame = frame
        try:
            # only blocks with contents newer than those last recorded (a block that lags comes a call later)
            names, last = [], self._stamps
            for n in self.recorded.due(frame, self.options.image_every):
                stamp = seg.frame_of(n)
                if stamp > last.get(n, -1):
                    last[n] = stamp
                    names.append(n)
            if self._writer is not None:
                self._writer.write(frame, *frame_data(seg, names))
                return
            if not self._credits.acquire(False):
                self._tell()  # every full slot must be known to the recorder before the ring waits for one
                t0 = time.perf_counter()
                self.waits += 1
                evidence = Evidence(self._proc.pid)
                while not self._credits.acquire(timeout=CREDIT_POLL_S):
                    self._check_recorder(evidence)
                self.wait_s += time.perf_counter() - t0
            slot = self._sent % self._slots.slots  # credits come back in order: this slot is free
            self._slots.put(seg, slot, frame, names)
            self._sent += 1
            self._slots.count = self._sent
            if self._sent - self._told >= self._notify_frames or time.monotonic() - self._t_told >= NOTIFY_S:
                self._tell()
        except (OSError, RecorderGone) as exc:  # a dead, stopped or stalled recorder, a full disk: no traceback
            self._failed = True
            self._problem = (self._why(exc), frame)
            log.error("recording to %s stopped at frame %d: %s; the run goes on without recording", self.path,
                      frame, self._problem[0])
            self._end_recorder()
        except Exception as exc:  # noqa: BLE001 - a recording failure must not end the run
            self._failed = True
            self._problem = (f"{type(exc).__name__}: {exc}", frame)
            log.exception("recording to %s failed at frame %d; the run goes on without recording", self.path, frame)

    def _check_recorder(self, evidence: Evidence) -> None:
        """Raise :class:`RecorderGone` if the recorder died, is stopped, or makes no progress (called while the
        sink waits for a free slot: the recorder has frames to write)."""
        p = self._proc
        if not p.is_alive():
            how = "a write error" if p.exitcode == EXIT_WRITE_FAILED else f"exit {p.exitcode}"
            raise RecorderGone(f"the recorder process ended ({how})")
        if is_stopped(p.pid):
            self._stopped_at = self._stopped_at or time.monotonic()
            if time.monotonic() - self._stopped_at > CONFIRM_S:
                raise RecorderGone(f"the recorder process (pid {p.pid}) is stopped (SIGSTOP)")
            return
        self._stopped_at = 0.0
        idle = evidence.idle_s()
        if idle > RECORDER_IDLE_S:
            raise RecorderGone(f"the recorder process (pid {p.pid}) made no progress: no CPU time in {idle:.1f} s "
                               "with frames to write")

    def _why(self, exc: Exception) -> str:
        if isinstance(exc, ConnectionError) and self._proc is not None:  # the pipe to a recorder that ended
            self._proc.join(CREDIT_POLL_S)
            code = self._proc.exitcode
            return "the recorder process ended (" + ("a write error" if code == EXIT_WRITE_FAILED else
                                                     f"exit {code}") + ")"
        return str(write_error(exc, self.path)) if isinstance(exc, OSError) else str(exc)

    def _end_recorder(self) -> None:
        if self._proc is not None and self._proc.exitcode is None:
            end_process(self._proc, END_GRACE_S)

    def _wait_recorder(self) -> str:
        """Wait for the recorder to end; "" when it did, else why it was given up on: stopped, no progress for
        RECORDER_IDLE_S (cosim.runtime.liveness.Evidence), or CLOSE_CPU_S of its CPU time spent finishing. A
        recorder slowed by a busy machine is waited for: the recording is whole."""
        p = self._proc
        evidence, t_stopped = Evidence(p.pid), None
        while True:
            p.join(CREDIT_POLL_S)
            if p.exitcode is not None:
                return ""
            now = time.monotonic()
            if is_stopped(p.pid):
                t_stopped = t_stopped or now
                if now - t_stopped > CONFIRM_S:
                    return "is stopped (SIGSTOP)"
                continue
            t_stopped = None
            idle = evidence.idle_s()
            if idle > RECORDER_IDLE_S:
                return f"made no progress (no CPU time in {idle:.1f} s)"
            if evidence.cpu_s > CLOSE_CPU_S:
                return f"did not finish within {CLOSE_CPU_S:.0f} s of its CPU time"

    def _note(self, why: str) -> None:
        """Keep the first reason the recording is not whole."""
        if self._problem is None:
            self._problem = (why, self._last_frame)

    @property
    def error(self) -> RecordingFailed | None:
        """Why the recording is not whole (a dead, stopped or stalled recorder, a write error), or None. Read by
        the launcher after :meth:`close`: the run then ends failed, with every other output written."""
        if self._problem is None:
            return None
        why, frame = self._problem
        return RecordingFailed(f"recording {self.path} is incomplete: {why}", frame=frame)

    def _tell(self) -> None:
        """Tell the recorder how many frames have been put (one small message; a no-op when it knows)."""
        if self._sent != self._told:
            self._conn.send_bytes(_COUNT.pack(self._sent))
            self._told = self._sent
        self._t_told = time.monotonic()

    def _release_slots(self) -> None:
        if self._slots is not None:
            self._slots.close()
            self._slots.unlink()
            self._slots = None

    def close(self) -> None:
        """Let the recorder write everything it was sent, finish the file, and end. Idempotent."""
        if self._closed:
            return
        self._closed = True
        if self._writer is not None:
            try:
                self._writer.close()
            except OSError as exc:
                self._note(str(write_error(exc, self.path)))
                log.error("recording to %s could not be finished: %s", self.path, self._problem[0])
            return
        try:
            self._tell()
            self._conn.send_bytes(b"")  # the end mark
        except OSError:
            pass
        self._conn.close()
        why = self._wait_recorder()
        if why:
            self._note(f"the recorder process {why}")
            log.error("the recorder of %s %s; ending it (the file keeps the frames flushed so far)", self.path, why)
            self._end_recorder()
        elif self._proc.exitcode == EXIT_WRITE_FAILED:
            self._note(f"the recorder process stopped on a write error writing {self.path} (its message is above)")
            log.error("the recorder of %s stopped on a write error (see above)", self.path)
        elif self._proc.exitcode != 0:
            self._note(f"the recorder process ended with exit {self._proc.exitcode}")
            log.error("the recorder of %s ended with exit %s", self.path, self._proc.exitcode)
        if self.waits:
            log.info("recording %s: the ring waited %d times (%.2f s in all) for a free frame slot", self.path,
                     self.waits, self.wait_s)
        self._release_slots()


def mcap_sink(options: RecordOptions | None = None):
    """A launcher sink factory: ``launch(..., sinks=[mcap_sink(RecordOptions(...))])``."""

    def factory(scenario, run_dir, segment) -> McapRecorder:
        return McapRecorder(scenario, run_dir, segment, options)

    return factory
