"""Liveness apart from slowness (docs/architecture.md): heartbeats, stopped processes, bounded ends.

A child beats from a thread of its own (:class:`Heartbeat`): every ``BEAT_S`` it stamps CLOCK_MONOTONIC (one
clock for every process of the machine) into its slot's ``alive_ns``, whatever its frame work does, so a long
frame still beats. A process stopped by SIGSTOP stops every thread, and one deadlocked while holding the GIL
stops the beating thread too: its beat ages. :class:`Watch` (run by the supervisor between wait slices) names
such a process once its beat is older than ``STALL_S`` and it neither ran nor used CPU time for ``CONFIRM_S``
more (so a supervisor that was itself descheduled does not blame a child that was not, and a child busy in one
long call that keeps the GIL - a big GL draw - counts as slow, not hung), and names a process the kernel reports
stopped
(``/proc/<pid>/stat`` state ``T``) as soon as it is, before it ever beat included. A process that beats but does
not finish its frame is left to the hand-off timeout (cosim.runtime.lockstep).

:func:`end_process` ends any child in bounded time: SIGTERM, then SIGKILL (which also ends a stopped process).
"""
from __future__ import annotations

import logging
import os
import signal
import threading
import time
from typing import Callable, Mapping, Sequence

from cosim.errors import ParticipantCrashed, ParticipantDied, ParticipantHung, RunError
from shm_schema import Phase, Segment
from shm_schema.layout import SLOT_WORD

__all__ = ["BEAT_S", "STALL_S", "CONFIRM_S", "Heartbeat", "Watch", "process_state", "cpu_ticks", "is_stopped",
           "end_process", "stop_processes", "child_failure", "ring_holder"]

#: period of a child's liveness beat, s
BEAT_S = 0.1
#: a beat older than this means the process is not running (stopped, deadlocked), s
STALL_S = 1.0
#: a stall is confirmed only if it still holds this much later (the supervisor may itself have been paused), s
CONFIRM_S = 0.25

log = logging.getLogger("cosim.runtime.liveness")

_ALIVE = SLOT_WORD["alive_ns"]
_NS = 1e9


class Heartbeat:
    """A daemon thread stamping ``time.monotonic_ns()`` into ``words[alive_ns]`` every ``period_s``."""

    def __init__(self, words: memoryview, period_s: float = BEAT_S):
        self._words = words
        self._period = period_s
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="cosim-heartbeat", daemon=True)

    def start(self) -> "Heartbeat":
        self._words[_ALIVE] = time.monotonic_ns()
        self._thread.start()
        return self

    def _run(self) -> None:
        words, clock = self._words, time.monotonic_ns
        while not self._stop.wait(self._period):
            words[_ALIVE] = clock()

    def stop(self) -> None:
        """End the thread (idempotent); the slot keeps the last beat."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(2 * self._period)


def _proc_stat(pid: int) -> tuple[str, int]:
    """(one-letter state, user + system CPU clock ticks) of ``pid``; ("", -1) when it cannot be read."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            raw = f.read()
    except OSError:
        return "", -1
    # "pid (comm) S ppid ...": comm may hold spaces and parentheses; the state follows the last ')', and utime,
    # stime are fields 14 and 15 (the 12th and 13th after the state)
    fields = raw[raw.rfind(b")") + 2:].split()
    try:
        return fields[0].decode("ascii", "replace"), int(fields[11]) + int(fields[12])
    except (IndexError, ValueError):
        return fields[0].decode("ascii", "replace") if fields else "", -1


def process_state(pid: int) -> str:
    """The kernel's one-letter state of ``pid`` (``R`` running, ``S`` sleeping, ``T`` stopped, ``Z`` zombie...),
    or ``""`` when it cannot be read (gone, not Linux)."""
    return _proc_stat(pid)[0]


def cpu_ticks(pid: int) -> int:
    """User + system CPU time of ``pid`` in clock ticks (os.sysconf("SC_CLK_TCK") a second), -1 if unknown."""
    return _proc_stat(pid)[1]


def is_stopped(pid: int) -> bool:
    """Whether ``pid`` is stopped by a signal (SIGSTOP, SIGTSTP) or a tracer."""
    return process_state(pid) in ("T", "t")


class Watch:
    """Names a ring child that stopped running; call :meth:`check` between wait slices (it raises)."""

    def __init__(self, seg: Segment, procs: Mapping[str, object], clock: Callable[[], int] = time.monotonic_ns):
        self._seg = seg
        self._procs = procs
        self._clock = clock
        self._words = {n: seg.slot_words(n) for n in procs}
        #: name -> (beat seen stale, its CPU ticks then, when it was first seen so) for the confirmation
        self._suspect: dict[str, tuple[int, int, int]] = {}

    def check(self) -> None:
        """Raise :class:`ParticipantHung` for a child stopped by a signal, or whose beat stalled (confirmed)."""
        now = self._clock()
        for name, proc in self._procs.items():
            pid = getattr(proc, "pid", None)
            if pid is None or getattr(proc, "exitcode", None) is not None:
                continue
            words = self._words[name]
            if int(words[SLOT_WORD["phase"]]) in (Phase.DONE, Phase.CLOSED, Phase.FAILED):
                continue
            beat = int(words[_ALIVE])
            state, ticks = _proc_stat(pid)
            stopped = state in ("T", "t")
            stale = beat > 0 and (now - beat) / _NS > STALL_S
            if not (stopped or stale):
                self._suspect.pop(name, None)
                continue
            seen = self._suspect.get(name)
            # a stale beat in a child that runs (state R) or whose CPU time still goes is a busy child (one long
            # call that keeps the GIL): slow, not hung; the hand-off timeout covers it
            busy = not stopped and (state == "R" or (seen is not None and ticks != seen[1]))
            if seen is None or seen[0] != beat or busy:
                self._suspect[name] = (beat, ticks, now)
                continue
            if (now - seen[2]) / _NS < CONFIRM_S:
                continue
            raise self._hung(name, pid, words, beat, now, stopped)

    def _hung(self, name: str, pid: int, words, beat: int, now: int, stopped: bool) -> ParticipantHung:
        frame = int(words[SLOT_WORD["frame"]])
        phase = int(words[SLOT_WORD["phase"]])
        label = Phase.NAMES[phase] if 0 <= phase < len(Phase.NAMES) else str(phase)
        where = f"during frame {frame} ({label})" if frame >= 0 else f"before frame 0 ({label})"
        since = f"its last heartbeat was {(now - beat) / _NS:.1f} s ago" if beat > 0 else "it never beat"
        if stopped:
            text = f"{name} (pid {pid}) is stopped {where} (by SIGSTOP, Ctrl-Z or a debugger); {since}"
        else:
            text = (f"{name} (pid {pid}) stopped beating {where}: deadlocked, or blocked in code that holds the "
                    f"GIL; {since}")
        return ParticipantHung(text, process=name, frame=frame)


def end_process(proc, grace_s: float) -> None:
    """End ``proc`` (a multiprocessing process) in bounded time: SIGTERM, ``grace_s`` to go, then SIGKILL (which
    also ends a stopped process; SIGTERM stays pending in one). Never blocks longer than ``grace_s`` + 2 s."""
    if proc.exitcode is not None or proc.pid is None:
        return
    try:
        if is_stopped(proc.pid):
            os.kill(proc.pid, signal.SIGKILL)
        else:
            proc.terminate()
            proc.join(grace_s)
            if proc.exitcode is None:
                proc.kill()
    except ProcessLookupError:
        pass
    proc.join(2.0)


def child_failure(name: str, proc, seg: Segment) -> RunError:
    """The error of child ``name`` that ended before its last frame: its own report (with traceback) when it
    wrote one, else how it died (signal or exit status), the frame and the phase."""
    err = seg.read_error(name)
    slot = seg.slot(name)
    frame = int(slot["frame"])
    if err:
        return ParticipantCrashed(
            f"{name} raised {err['type']} at frame {err['frame']}: {err['message']}",
            process=name, frame=int(err["frame"]), detail=err.get("traceback", ""))
    code = proc.exitcode
    how = f"signal {signal.Signals(-code).name}" if code is not None and code < 0 else f"exit status {code}"
    phase = Phase.NAMES[int(slot["phase"])] if 0 <= int(slot["phase"]) < len(Phase.NAMES) else "?"
    return ParticipantDied(f"{name} (pid {proc.pid}) died with {how} during frame {frame} (phase {phase})",
                           process=name, frame=frame)


def ring_holder(seg: Segment, members: Sequence[str]) -> str | None:
    """The member that holds up the run (the one a hand-off timeout is about): of the members starting or stepping
    (a member blocked on a reader, under the pipelined schedule, says waiting), the one busy the longest (its slot's
    ``heartbeat_ns`` is stamped when it starts a step; 0 before its first); None when every member waits (then no
    member is at fault)."""
    busy = [(int(seg.slot(n)["heartbeat_ns"]), n) for n in members
            if int(seg.slot(n)["phase"]) in (Phase.STARTING, Phase.STEPPING)]
    return min(busy)[1] if busy else None


def stop_processes(procs: Mapping[str, object], *, graceful: bool, join_timeout_s: float, grace_s: float,
                   hung: Sequence[str] = ()) -> None:
    """Join children after a clean finish; otherwise (or past ``join_timeout_s``) end them: SIGTERM, ``grace_s``,
    then SIGKILL, which also ends a stopped one. The ``hung`` ones (stopped or deadlocked: SIGTERM cannot reach
    their code) and any stopped one get SIGKILL at once. Never leaves one, never waits unbounded."""
    if graceful:
        deadline = time.monotonic() + join_timeout_s
        for p in procs.values():
            p.join(max(0.0, deadline - time.monotonic()))
    alive = [p for p in procs.values() if p.is_alive()]
    for name, p in procs.items():
        if p not in alive or p.exitcode is not None:
            continue
        try:
            if name in hung or is_stopped(p.pid):
                p.kill()
            else:
                p.terminate()
        except ProcessLookupError:
            pass
    deadline = time.monotonic() + grace_s
    for p in alive:
        p.join(max(0.0, deadline - time.monotonic()))
    for p in procs.values():
        if p.is_alive():
            log.warning("%s (pid %s) did not end on SIGTERM; killing it", p.name, p.pid)
            end_process(p, 0.0)
