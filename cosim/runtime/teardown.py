"""Teardown of one run (cosim.runtime.launcher): every process ended in bounded time, the last outputs written,
the segment unlinked; the figures of a completed run drawn (cosim.runtime.figures). Back within 2 s of a fault.

Order: the frame sinks close (a recording not written whole is reported here); the ring children end (a hung
one - stopped, deadlocked - gets SIGKILL at once); the observers are told the run has ended (a viewer shows the
last frame to a watching page); the last rows, the maps and the summary are written and the segment unlinked;
the figures of a completed run are drawn; the observers are ended (OBSERVER_GRACE_S after a completed run,
TERMINATE_GRACE_S after a failed one). The error is the first of: the run's own, a stop signal, a sink's, a
write error, and names the process at fault (:func:`at_fault`).
"""
from __future__ import annotations

import json
import logging
import multiprocessing as mp
import time
from pathlib import Path
from typing import Mapping

from cosim.errors import OutputError, ParticipantHung, RunError, RunInterrupted

from .figures import PENDING, draw_figures, figures_plan
from .files import atomic_write
from .liveness import stop_processes
from .outcome import outcome_line
from .outputs import finish_outputs
from .runstate import RunState
from .signals import StopSignals
from .specs import SUPERVISOR

__all__ = ["tear_down", "at_fault", "write_run_json", "EXIT_OK", "EXIT_RUN_ERROR", "EXIT_INTERRUPTED",
           "JOIN_TIMEOUT_S", "TERMINATE_GRACE_S", "OBSERVER_GRACE_S"]

log = logging.getLogger("cosim.runtime.launcher")

EXIT_OK, EXIT_RUN_ERROR, EXIT_INTERRUPTED = 0, 1, 130
#: CPU time a child may spend closing after the last frame (GL teardown) before it is terminated, s; a child that
#: makes progress closing is waited for, one that makes none is ended (cosim.runtime.liveness.stop_processes)
JOIN_TIMEOUT_S = 10.0
#: how long a terminated child gets before SIGKILL, s
TERMINATE_GRACE_S = 0.5
#: how long an observer may take to end after the SIGTERM that tells it a completed run has ended, s (the viewer
#: shows the last frame to a page that is watching, cosim.viewer.server.LINGER_S or longer for a page that polls
#: late, at most LINGER_MAX_S = 8 s, then drains; an observer that is done ends at once and a viewer nobody
#: watches does not linger); after a failed run, TERMINATE_GRACE_S (the launcher is back within 2 s of a fault)
OBSERVER_GRACE_S = 10.0


def at_fault(run: RunState, error: RunError) -> RunError:
    """``error`` naming the process at fault: an error that names no process (a write error) names the supervisor,
    which writes the outputs. (A hang or a runaway is named on its member by the liveness watch already.)"""
    if not error.process:
        error.process = SUPERVISOR
    return error


def _close_sinks(run: RunState) -> RunError | None:
    """Close every frame sink; the first failure one reports (``sink.error``: a recording not written whole)."""
    failure = None
    for sink in run.frame_sinks:
        close = getattr(sink, "close", None)
        try:
            if close is not None:
                close()
        except Exception:  # noqa: BLE001 - a sink's close must not hide the run's outcome
            log.exception("closing a frame sink failed")
        failure = failure or getattr(sink, "error", None)
    return failure


def tear_down(run: RunState, error: RunError | None) -> tuple[dict, RunError | None, int]:
    """End every process (bounded), write the last rows, maps and the final summary, unlink the segment; draw the
    figures of a completed run only (cosim.runtime.figures: a failed or stopped run returns at once). Signals
    meanwhile are only counted (a first one cuts the figures short); the exit status is 130 whenever a stop
    signal came."""
    t_down = time.perf_counter()
    wall = t_down - run.t_start if run.t_start else 0.0
    sink_error = _close_sinks(run)
    hung = (error.process,) if isinstance(error, ParticipantHung) else ()
    stop_processes(run.procs, graceful=error is None, join_timeout_s=JOIN_TIMEOUT_S, grace_s=TERMINATE_GRACE_S,
                   hung=hung, by_progress=True)
    # the segment is final: tell the observers now (a viewer shows the last frame), end them after the outputs
    observers_until = time.monotonic() + (OBSERVER_GRACE_S if error is None else TERMINATE_GRACE_S)
    _tell_observers(run.watchers)
    if run.recorder is not None:
        run.recorder.finish()
    t_stopped = time.perf_counter()
    if error is None and run.stop.signum is not None:
        error = run.stop.error(run.frame)
    error = error or sink_error
    if error is not None:
        log.error("run failed: %s", error)
        if error.detail:
            log.error("traceback of %s:\n%s", error.process, error.detail)
        if getattr(error, "threads", None):  # log.txt only: no child's detail on the console for a hang
            log.info("the threads of %s when it was named:\n%s", error.process, "\n".join(error.threads))
    figures = figures_plan(run.run_dir, run.scenario, run.recorder, error)
    try:
        summary, failure = finish_outputs(run.run_dir, run.scenario, run.recorder, run.ring, wall_time_s=wall,
                                          error=error, files=run.files, extra={"figures": figures},
                                          reserve=figures["status"] == PENDING)
    finally:
        if run.seg is not None:
            run.seg.close()
            run.seg.unlink()
            _end_run_json(run.run_dir)
    log.info("%s", outcome_line(summary.get("outcome")))
    t_outputs = time.perf_counter()
    if failure is None and figures["status"] == PENDING:
        summary, failure = draw_figures(run.run_dir, run.scenario, summary, run.recorder, run.stop.raising)
    if failure is not None:
        log.error("%s", failure)
        error = error or at_fault(run, failure)
    stop_processes(run.watchers, graceful=True, join_timeout_s=max(0.0, observers_until - time.monotonic()),
                   grace_s=0.0)
    code = _exit_code(error, run.stop)
    t_end = time.perf_counter()
    log.info("run %s %s in %.2f s (exit %d); start-up %.2f s to the first frame (set-up before spawning %.2f s), "
             "shut-down %.2f s (children %.2f s, outputs %.2f s, figures and observers %.2f s); launcher cpu %.2f s",
             run.run_dir.name, "completed" if error is None else "stopped", wall, code, run.t_first - run.t_enter,
             run.t_start - run.t_enter if run.t_start else 0.0, t_end - t_down, t_stopped - t_down,
             t_outputs - t_stopped, t_end - t_outputs, time.process_time())
    return summary, error, code


def _exit_code(error: RunError | None, stop: StopSignals) -> int:
    if stop.signum is not None or isinstance(error, RunInterrupted):
        return EXIT_INTERRUPTED
    return EXIT_OK if error is None else EXIT_RUN_ERROR


def write_run_json(run_dir: Path, info: dict) -> None:
    atomic_write(run_dir / "run.json", json.dumps(info, indent=2) + "\n")


def _end_run_json(run_dir: Path) -> None:
    """Mark run.json ended (the segment is gone); a write error here is only logged."""
    try:
        info = json.loads((run_dir / "run.json").read_text())
        info["ended"] = True
        write_run_json(run_dir, info)
    except (OSError, ValueError, OutputError) as exc:
        log.warning("could not mark run.json ended: %s", exc)


def _tell_observers(watchers: Mapping[str, mp.process.BaseProcess]) -> None:
    """SIGTERM every observer still running: the run has ended."""
    for w in watchers.values():
        if w.exitcode is None:
            try:
                w.terminate()
            except ProcessLookupError:
                pass
