"""The recording sink of the launcher (``launch(..., sinks=[mcap_sink()])``) and its recorder process.

The supervisor calls the sink after each completed frame while it holds the token, so it sees every frame
consistently without a seqlock retry. The sink only copies the frame's blocks (:func:`capture`, a memcpy) and
sends them down a pipe; a recorder process (spawned, like the ring's children) encodes (PNG/JPEG, base64, JSON,
zstd) and writes. The ring is sequential, so on a 2-core machine the recorder uses the core the ring leaves
idle, and it shares no GIL with the supervisor. At most ``queue_frames`` frames are in flight (a semaphore of
credits): when encoding cannot keep up, the sink waits, so a recording never loses a frame. ``queue_frames=0``
writes synchronously inside the sink, with no process.

Ends: ``close`` (end of run, failure, stop) sends the end mark and waits for the recorder to write every frame
it was sent and finish the file. If the launcher itself is killed, the recorder sees the pipe close, writes
what it has received and finishes the file. A recording failure (disk full, a dead recorder) is logged once and
recording stops; the run goes on.
"""
from __future__ import annotations

import logging
import multiprocessing as mp
import queue
import threading
from pathlib import Path

from shm_schema import Schema, Segment

from .writer import DEFAULT_NAME, McapWriter, Recorded, RecordOptions, capture

__all__ = ["McapRecorder", "mcap_sink", "CREDIT_POLL_S", "CLOSE_TIMEOUT_S"]

log = logging.getLogger("cosim.recording")

#: slice of the sink's wait for a credit, s: bounds how late a dead recorder is noticed
CREDIT_POLL_S = 0.5
#: how long ``close`` waits for the recorder to write what it was sent and finish the file, s
CLOSE_TIMEOUT_S = 120.0


def _recorder_main(conn, credits, scenario_json: str, schema_bytes: bytes, path: str, options: RecordOptions,
                   run_id: str, fingerprint: str) -> None:
    """Recorder process: a receiving thread keeps the pipe drained; this thread encodes and writes."""
    import signal

    from cosim.config import Scenario

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the launcher handles Ctrl-C and then closes us
    scenario = Scenario.model_validate_json(scenario_json)
    writer = McapWriter(scenario, Schema.decode(schema_bytes), Path(path), options, run_id, fingerprint,
                        flush_s=options.flush_s)
    inbox: queue.Queue = queue.Queue()

    def receive() -> None:
        while True:
            try:
                item = conn.recv()
            except (EOFError, OSError):
                item = None
            inbox.put(item)
            if item is None:
                return

    threading.Thread(target=receive, name="recorder-recv", daemon=True).start()
    try:
        while True:
            item = inbox.get()
            if item is None:
                break
            writer.write(item)
            credits.release()
            if inbox.empty():
                writer.flush()  # idle: put everything on disk; busy: at most every flush_s
    finally:
        writer.close()


class McapRecorder:
    """The per-frame sink: capture in the supervisor, encode and write in the recorder process."""

    def __init__(self, scenario, run_dir: Path, segment: Segment, options: RecordOptions | None = None):
        self.options = options or RecordOptions()
        self.path = Path(self.options.path) if self.options.path else Path(run_dir) / DEFAULT_NAME
        self.recorded = Recorded.of(segment.schema)
        self._failed = False
        self._closed = False
        self._writer: McapWriter | None = None
        self._proc = None
        if self.options.queue_frames == 0:
            self._writer = McapWriter(scenario, segment.schema, self.path, self.options, segment.run_id,
                                      segment.fingerprint)
            return
        ctx = mp.get_context("spawn")
        self._credits = ctx.Semaphore(self.options.queue_frames)
        recv, self._conn = ctx.Pipe(duplex=False)
        self._proc = ctx.Process(target=_recorder_main, name="cosim-recorder", daemon=True,
                                 args=(recv, self._credits, scenario.model_dump_json(), segment.schema.encoded,
                                       str(self.path), self.options, segment.run_id, segment.fingerprint))
        self._proc.start()
        recv.close()

    def __call__(self, seg: Segment, frame: int) -> None:
        """Record completed frame ``frame`` (called by the supervisor while it holds the token)."""
        if self._failed or self._closed:
            return
        try:
            item = capture(seg, self.recorded, frame, self.options.image_every)
            if self._writer is not None:
                self._writer.write(item)
                return
            while not self._credits.acquire(timeout=CREDIT_POLL_S):
                if not self._proc.is_alive():
                    raise RuntimeError(f"the recorder process died (exit {self._proc.exitcode})")
            self._conn.send(item)
        except Exception:  # noqa: BLE001 - a recording failure must not end the run
            self._failed = True
            log.exception("recording to %s failed at frame %d; the run goes on without recording", self.path, frame)

    def close(self) -> None:
        """Let the recorder write everything it was sent, finish the file, and end. Idempotent."""
        if self._closed:
            return
        self._closed = True
        if self._writer is not None:
            self._writer.close()
            return
        try:
            self._conn.send(None)
        except OSError:
            pass
        self._conn.close()
        self._proc.join(CLOSE_TIMEOUT_S)
        if self._proc.is_alive():
            log.error("the recorder of %s did not finish in %.0f s; terminating it", self.path, CLOSE_TIMEOUT_S)
            self._proc.terminate()
            self._proc.join(5)
        elif self._proc.exitcode != 0:
            log.error("the recorder of %s ended with exit %s", self.path, self._proc.exitcode)


def mcap_sink(options: RecordOptions | None = None):
    """A launcher sink factory: ``launch(..., sinks=[mcap_sink(RecordOptions(...))])``."""

    def factory(scenario, run_dir, segment) -> McapRecorder:
        return McapRecorder(scenario, run_dir, segment, options)

    return factory
