"""Liveness by evidence of progress (docs/reliability.md): heartbeats, CPU time, stopped processes, bounded ends.

A busy machine (a laptop with a browser open, a shared CI runner) slows every process; only a process that makes
no progress is at fault. The evidence is the kernel's:

* A child beats from a thread of its own (:class:`Heartbeat`): every ``BEAT_S`` it stamps CLOCK_MONOTONIC into its
  slot's ``alive_ns`` and, once, its kernel thread id into ``beat_tid``. A beat that ages says the process is not
  running Python (stopped, deadlocked while holding the GIL, busy in one long call that keeps it, or starved).
* The working threads' CPU time (every thread of the process but the heartbeat's, from
  ``/proc/<pid>/task/<tid>/schedstat``, nanoseconds) and their states (``R`` runnable, ``D`` in I/O) say which: a
  process whose working threads gain CPU time, or wait for a core, or wait for the disk, makes progress, however
  slowly; so does one whose heartbeat thread waits for a core and has had none since the last look (preempted
  while it holds the GIL, it keeps the working threads asleep on the GIL); one whose working threads all sleep
  without CPU time is blocked.

:class:`Watch` (run by the supervisor between wait slices) names a ring member as hung when:

* the kernel reports it stopped (``T``: SIGSTOP, Ctrl-Z, a debugger), confirmed ``CONFIRM_S`` later;
* it is starting or stepping and its working threads gained no CPU time, and none was runnable, for ``IDLE_S``
  and at least ``IDLE_LOOKS`` looks in a row (a GIL deadlock: its beat ages too; a lock deadlock or a wait on
  something outside the run: it still beats). The looks count because the watch judges only what it saw: a
  supervisor starved itself looks seconds apart, and two looks a second apart prove nothing of the time between;
* it spent more than the scenario's ``timing.handoff_timeout_s`` of its own CPU time on one frame (a runaway
  loop; :class:`cosim.errors.HandoffTimeout`), or more than ``timing.startup_timeout_s`` of CPU time starting.

A member that waits for a peer is never judged: the peer is. So no wait of the ring has a wall-clock deadline: a
starved member is waited for, a hung one is named on the right member. While members start, the watch reports
every ``STARTUP_REPORT_S`` what they do (``activity``: "compiling shaders"), how long and how much CPU so far.

:func:`end_process` ends any child in bounded time: SIGTERM, then SIGKILL (which also ends a stopped process).
"""
from __future__ import annotations

import collections
import logging
import os
import signal
import threading
import time
from dataclasses import dataclass, field
from typing import Callable, Mapping, Sequence

from cosim.errors import HandoffTimeout, ParticipantCrashed, ParticipantDied, ParticipantHung, RunError
from shm_schema import Phase, Segment
from shm_schema.layout import SLOT_WORD

from .threadreport import read_proc, stat_fields, thread_report

__all__ = ["BEAT_S", "STALL_S", "CONFIRM_S", "IDLE_S", "IDLE_LOOKS", "LOOK_AFTER_S", "STARTUP_REPORT_S", "Heartbeat", "Watch",
           "Progress", "Evidence", "process_state", "cpu_ticks", "is_stopped", "threads_progress", "thread_progress",
           "end_process",
           "stop_processes", "child_failure"]

#: period of a child's liveness beat, s
BEAT_S = 0.1
#: a beat older than this says the process is not running Python (stopped, deadlocked, starved, in a long call), s
STALL_S = 1.0
#: a stop seen by the kernel is confirmed only if it still holds this much later, s
CONFIRM_S = 0.25
#: a starting or stepping member whose working threads gain no CPU time and wait for no core for this long is
#: hung, s
IDLE_S = 1.0
#: a member is looked at (its threads read from /proc) only once it has been in one phase and frame this long, s:
#: a healthy ring moves on far sooner, so the supervisor reads nothing on its hot path
LOOK_AFTER_S = 0.25
#: how often a member under look is sampled, s
SAMPLE_S = 0.1
#: a member is idle only once this many looks in a row saw no progress: the verdict rests on what the watch saw,
#: and a supervisor starved itself (its looks seconds apart) waits for as many looks as a quiet one takes in IDLE_S
IDLE_LOOKS = 5
#: while members start, the watch reports their activity after this long and every this long again, s
STARTUP_REPORT_S = 5.0
#: CPU time below this over IDLE_S is no progress (a timer thread of a library), ns
_EPS_NS = 2_000_000
#: samples of a member kept for the report of a hang
_HISTORY = 16

log = logging.getLogger("cosim.runtime.liveness")

_ALIVE, _TID = SLOT_WORD["alive_ns"], SLOT_WORD["beat_tid"]
_PHASE, _FRAME, _HEARTBEAT = SLOT_WORD["phase"], SLOT_WORD["frame"], SLOT_WORD["heartbeat_ns"]
_NS = 1e9
_TICK_NS = 1e9 / os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 1e7
#: phases in which a member does its own work (judged); a waiting member waits for a peer (not judged)
_WORKING = (Phase.IDLE, Phase.STARTING, Phase.STEPPING)
_STARTING = (Phase.IDLE, Phase.STARTING)


class Heartbeat:
    """A daemon thread stamping ``time.monotonic_ns()`` into ``words[alive_ns]`` every ``period_s``, its kernel
    thread id into ``words[beat_tid]`` first."""

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
        words[_TID] = threading.get_native_id()
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
        fields = stat_fields(read_proc(f"/proc/{pid}/stat"))
    except OSError:
        return "", -1
    # utime, stime are fields 14 and 15 of the line (the 12th and 13th after the state)
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


def _thread(pid: int, tid: int) -> tuple[int, bytes]:
    """(CPU time of thread ``tid`` of ``pid``, ns: its ``schedstat`` (exact), or its ``stat`` ticks where there is
    none; its one-letter state). Raises OSError (and IndexError, ValueError) when it cannot be read."""
    base = f"/proc/{pid}/task/{tid}/"
    fields = stat_fields(read_proc(base + "stat"))
    try:
        cpu = int(read_proc(base + "schedstat").split()[0])
    except (OSError, IndexError, ValueError):
        cpu = int((int(fields[11]) + int(fields[12])) * _TICK_NS)
    return cpu, fields[0]


def threads_progress(pid: int, skip_tid: int = 0) -> tuple[int, bool]:
    """(CPU time of ``pid``'s threads but ``skip_tid``, ns; whether one of them is runnable or in I/O: ``R`` or
    ``D``). (-1, False) when the process cannot be read (gone)."""
    try:
        tids = os.listdir(f"/proc/{pid}/task")
    except OSError:
        return -1, False
    cpu, busy = 0, False
    for tid in tids:
        if int(tid) == skip_tid:
            continue
        try:
            t_cpu, state = _thread(pid, int(tid))
        except (OSError, IndexError, ValueError):  # a thread that ended meanwhile
            continue
        cpu += t_cpu
        busy = busy or state in (b"R", b"D")
    return cpu, busy


def thread_progress(pid: int, tid: int) -> tuple[int, bool]:
    """(CPU time of thread ``tid`` of ``pid``, ns; whether it is runnable, ``R``); (-1, False) when it cannot be
    read (no such thread)."""
    try:
        cpu, state = _thread(pid, tid)
    except (OSError, IndexError, ValueError):
        return -1, False
    return cpu, state == b"R"


@dataclass
class Progress:
    """What the watch knows of one member since it entered its current (phase, frame, step): when, and the CPU
    evidence sampled since."""

    key: tuple[int, int, int]
    since_ns: int
    cpu0_ns: int = -1
    cpu_ns: int = -1
    moved_ns: int = 0
    idle_looks: int = 0
    sampled_ns: int = 0
    stopped_ns: int = 0
    reported_ns: int = 0
    beat_cpu_ns: int = -1
    #: the latest samples, (time ns, working threads' CPU ns, one runnable, heartbeat thread's CPU ns, it runnable)
    history: collections.deque = field(default_factory=lambda: collections.deque(maxlen=_HISTORY))

    def sample(self, now: int, cpu: int, busy: bool, beat: tuple[int, bool] = (-1, False)) -> None:
        """Take one sample: progress when the working threads gained CPU time (more than _EPS_NS since the last
        progress) or one of them wants a core or waits for the disk, or the heartbeat thread waits for a core
        without having had one since the last sample (``beat``: its CPU time, ns, and whether it is runnable; see
        :meth:`beat_starved`); the first sample starts the count."""
        if self.cpu0_ns < 0:
            self.cpu0_ns = cpu
        self.history.append((now, cpu, busy) + tuple(beat))
        starved = self.beat_starved(*beat)
        if self.cpu_ns < 0 or busy or starved or cpu - self.cpu_ns > _EPS_NS:
            self.cpu_ns, self.moved_ns, self.idle_looks = cpu, now, 0
        else:
            self.idle_looks += 1
        self.sampled_ns = now

    def idle_s(self, now: int) -> float:
        """Seconds since the last progress, once IDLE_LOOKS samples in a row saw none (0.0 before: a verdict needs
        that many looks, however far apart a starved supervisor took them)."""
        return (now - self.moved_ns) / _NS if self.idle_looks >= IDLE_LOOKS else 0.0

    def beat_starved(self, cpu: int, runnable: bool) -> bool:
        """Whether the heartbeat thread waits for a core and has had none since the last sample. Starved while it
        holds the GIL (a busy machine preempted it mid-beat), it keeps the working threads asleep waiting for the
        GIL, with no CPU time and not runnable: the process is starved, not hung. In a GIL deadlock it is woken
        every few milliseconds by the GIL's own timed wait, so it gains CPU time between samples and is no
        evidence; its CPU time never counts as progress."""
        last, self.beat_cpu_ns = self.beat_cpu_ns, cpu
        return runnable and last >= 0 and cpu == last

    @property
    def cpu_s(self) -> float:
        """CPU time of the working threads since the first sample, s."""
        return max(0, self.cpu_ns - self.cpu0_ns) / _NS if self.cpu0_ns >= 0 else 0.0


class Evidence:
    """The progress of one process outside the ring (a recorder) by its threads' CPU time and states."""

    def __init__(self, pid: int, skip_tid: int = 0, clock: Callable[[], int] = time.monotonic_ns):
        self.pid, self._skip, self._clock = pid, skip_tid, clock
        self._p = Progress((0, 0, 0), clock())

    def idle_s(self) -> float:
        """Seconds since its working threads last gained CPU time or waited for a core or the disk, once IDLE_LOOKS
        calls in a row saw none (0.0 before; 0.0 when it cannot be read: a process that ended is for its exit status
        to tell)."""
        now = self._clock()
        cpu, busy = threads_progress(self.pid, self._skip)
        if cpu < 0:
            return 0.0
        self._p.sample(now, cpu, busy)
        return self._p.idle_s(now)

    @property
    def cpu_s(self) -> float:
        """CPU time of its working threads since the first :meth:`idle_s`, s."""
        return self._p.cpu_s


class Watch:
    """Names a ring member that makes no progress; call :meth:`check` between wait slices (it raises).

    ``frame_cpu_s`` / ``startup_cpu_s``: the CPU time a member may spend on one frame / on starting before it is
    a runaway (:class:`HandoffTimeout`); ``report(text)`` receives the start-up lines."""

    def __init__(self, seg: Segment, procs: Mapping[str, object], *, frame_cpu_s: float = float("inf"),
                 startup_cpu_s: float = float("inf"), report: Callable[[str], None] | None = None,
                 clock: Callable[[], int] = time.monotonic_ns):
        self._seg = seg
        self._procs = procs
        self._clock = clock
        self._frame_cpu_s, self._startup_cpu_s = frame_cpu_s, startup_cpu_s
        self._report = report
        self._words = {n: seg.slot_words(n) for n in procs}
        self._progress: dict[str, Progress] = {}

    def check(self) -> None:
        """Raise :class:`ParticipantHung` for a member stopped or blocked, :class:`HandoffTimeout` for a runaway."""
        now = self._clock()
        for name, proc in self._procs.items():
            pid = getattr(proc, "pid", None)
            if pid is None or getattr(proc, "exitcode", None) is not None:
                continue
            w = self._words[name]
            phase = int(w[_PHASE])
            if phase in (Phase.DONE, Phase.CLOSED, Phase.FAILED):
                continue
            # start-up is one span, from before the attach (IDLE) to ready
            key = (Phase.STARTING if phase in _STARTING else phase, int(w[_FRAME]), int(w[_HEARTBEAT]))
            p = self._progress.get(name)
            if p is None or p.key != key:
                p = self._progress[name] = Progress(key, now)
            if is_stopped(pid):
                p.stopped_ns = p.stopped_ns or now
                if (now - p.stopped_ns) / _NS >= CONFIRM_S:
                    raise self._hung(name, pid, w, now, stopped=True)
                continue
            p.stopped_ns = 0
            if phase not in _WORKING or (now - p.since_ns) / _NS < LOOK_AFTER_S:
                continue
            if (now - p.sampled_ns) / _NS >= SAMPLE_S:
                tid = int(w[_TID])
                cpu, busy = threads_progress(pid, tid)
                if cpu >= 0:
                    p.sample(now, cpu, busy, thread_progress(pid, tid) if tid else (-1, False))
            self._judge(name, pid, w, p, now, phase)

    def _judge(self, name: str, pid: int, w, p: Progress, now: int, phase: int) -> None:
        if p.cpu0_ns < 0:
            return
        idle_s = p.idle_s(now)
        if idle_s >= IDLE_S:
            raise self._hung(name, pid, w, now, stopped=False, idle_s=idle_s)
        starting = phase in _STARTING
        limit = self._startup_cpu_s if starting else self._frame_cpu_s
        if p.cpu_s > limit:
            frame = int(w[_FRAME])
            what = "starting" if starting else f"frame {frame}"
            key = "timing.startup_timeout_s" if starting else "timing.handoff_timeout_s"
            raise HandoffTimeout(f"{name} (pid {pid}) did not finish {what} within its CPU budget: "
                                 f"{p.cpu_s:.1f} s of its own CPU time ({key} = {limit:g} s); a loop that never "
                                 "ends?", process=name, frame=frame)
        if starting and self._report is not None:
            self._report_startup(name, p, now)

    def _report_startup(self, name: str, p: Progress, now: int) -> None:
        since = (now - p.since_ns) / _NS
        if since < STARTUP_REPORT_S or (now - p.reported_ns) / _NS < STARTUP_REPORT_S:
            return
        p.reported_ns = now
        doing = _activity(self._seg, name) or "importing its modules"
        self._report(f"{name}: {doing}, {since:.0f} s so far ({p.cpu_s:.1f} s of CPU time): waiting for it")

    def _hung(self, name: str, pid: int, w, now: int, *, stopped: bool, idle_s: float = 0.0) -> ParticipantHung:
        frame, phase = int(w[_FRAME]), int(w[_PHASE])
        beat = int(w[_ALIVE])
        label = Phase.NAMES[phase] if 0 <= phase < len(Phase.NAMES) else str(phase)
        if phase in _STARTING:
            doing = _activity(self._seg, name)
            where = "in start-up" + (f" ({doing})" if doing else "") + ", before frame 0"
        elif frame >= 0:
            where = f"during frame {frame} ({label})"
        else:
            where = f"before frame 0 ({label})"
        age = (now - beat) / _NS if beat > 0 else float("inf")
        since = f"its last heartbeat was {age:.1f} s ago" if beat > 0 else "it never beat"
        if stopped:
            text = f"{name} (pid {pid}) is stopped {where} (by SIGSTOP, Ctrl-Z or a debugger); {since}"
        elif age > STALL_S:
            text = (f"{name} (pid {pid}) stopped beating {where}: deadlocked, or blocked in code that holds the "
                    f"GIL; {since} and its threads used no CPU time for {idle_s:.1f} s")
        else:
            text = (f"{name} (pid {pid}) is blocked {where}: it beats, but its working threads used no CPU time "
                    f"for {idle_s:.1f} s (a deadlock on a lock, or a wait on something outside the run)")
        p = self._progress.get(name)
        return ParticipantHung(text, process=name, frame=frame,
                               threads=thread_report(pid) + (_samples(p, now, int(w[_TID])) if p else []))


def _samples(p: Progress, now: int, beat_tid: int) -> list[str]:
    """The watch's latest samples of a member, oldest first, for the report of a hang."""
    lines = [f"the watch's samples (heartbeat thread {beat_tid}), seconds before the verdict:"]
    for t, cpu, busy, beat_cpu, beat_runnable in p.history:
        lines.append(f"  -{(now - t) / _NS:.2f} s: working threads {cpu / 1e6:.1f} ms CPU"
                     f"{', one runnable' if busy else ''}; heartbeat {beat_cpu / 1e6:.1f} ms"
                     f"{', runnable' if beat_runnable else ''}")
    return lines


def _activity(seg: Segment, name: str) -> str:
    """What ``name`` says it is doing (its slot's ``activity``), "" when nothing."""
    raw = bytes(seg.slot(name)["activity"])
    return raw.rstrip(b"\0").decode("utf-8", "replace")


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


def stop_processes(procs: Mapping[str, object], *, graceful: bool, join_timeout_s: float, grace_s: float,
                   hung: Sequence[str] = (), by_progress: bool = False) -> None:
    """Join children after a clean finish; otherwise (or past ``join_timeout_s``) end them: SIGTERM, ``grace_s``,
    then SIGKILL, which also ends a stopped one. ``by_progress`` (ring members): after a clean finish a child
    closing (GL teardown, files) is waited for while it makes progress (:class:`Evidence`: CPU time, a wait for a
    core or the disk) and has used less than ``join_timeout_s`` of CPU time closing, so a busy machine never turns
    a clean end into a kill. The ``hung`` ones (stopped or deadlocked: SIGTERM cannot reach their code) and any stopped one get
    SIGKILL at once. Never leaves one, never waits on one that makes no progress."""
    if graceful and by_progress:
        _join_while_progressing(procs, join_timeout_s)
    elif graceful:
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


#: slice of the wait for children that close after a clean finish, s
_JOIN_POLL_S = 0.05


def _join_while_progressing(procs: Mapping[str, object], cpu_budget_s: float) -> None:
    """Wait for every child to exit while each one still running makes progress and stays within
    ``cpu_budget_s`` of CPU time; return as soon as all exited or one does not."""
    evidence = {n: Evidence(p.pid) for n, p in procs.items() if p.pid is not None and p.exitcode is None}
    while evidence:
        for n in list(evidence):
            p = procs[n]
            p.join(_JOIN_POLL_S / len(evidence))
            if p.exitcode is not None:
                del evidence[n]
                continue
            idle = evidence[n].idle_s()
            if is_stopped(p.pid) or idle > IDLE_S or evidence[n].cpu_s > cpu_budget_s:
                log.warning("%s (pid %s) %s while closing after the run; ending it", p.name, p.pid,
                            "is stopped" if is_stopped(p.pid) else f"made no progress for {idle:.1f} s"
                            if idle > IDLE_S else f"used {evidence[n].cpu_s:.1f} s of CPU time")
                return
