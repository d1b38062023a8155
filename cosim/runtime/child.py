"""Entry point of a participant's OS process (spawn context): attach, start, run the ring, report failures.

The child ignores SIGINT (the launcher coordinates a clean stop), turns SIGTERM into SystemExit so that
``close`` runs, asks the kernel to SIGTERM it if its parent (the launcher, or the fork server that exits with the
launcher: cosim.runtime.procstart) dies (PR_SET_PDEATHSIG), and appends its logs and
stray stdout/stderr to the run's log.txt. From its attach on, a thread beats in its header slot
(cosim.runtime.liveness.Heartbeat), so the launcher tells a stopped or deadlocked child from a slow one. Freed
memory stays in the heap (cosim.runtime.heap), so per-frame arrays reuse warm pages. Any
exception is written with its traceback into the process's error slot in the segment header before the process
exits with status 1. A clean child exits with status 0
right after closing, without the interpreter's module teardown.
"""
from __future__ import annotations

import ctypes
import logging
import os
import signal
import sys
import time
import traceback
from dataclasses import dataclass
from typing import Mapping

from cosim.errors import RunError
from cosim.scenario.config import Scenario
from shm_schema import Phase, Segment
from shm_schema.layout import ACTIVITY_BYTES

from .heap import keep_heap
from .liveness import Heartbeat
from .lockstep import RingPlan, Token, member_loop
from .logs import configure_logging
from .participant import activity, set_activity
from .pipeline import Gates, PipePlan
from .pipeline import member_loop as pipelined_loop
from .specs import ParticipantSpec

__all__ = ["ChildArgs", "child_main"]

_PR_SET_PDEATHSIG = 1


@dataclass(frozen=True)
class ChildArgs:
    """Everything a child needs; picklable for the spawn start method."""

    spec: ParticipantSpec
    scenario_json: str
    segment: str
    fingerprint: str
    plan: RingPlan | PipePlan
    semaphores: Mapping[str, object]
    log_path: str
    parent_pid: int
    #: wall-clock time (time.time(), s) at which the launcher started this process, for the start-up log line
    spawned_at_s: float


def _die_with_parent() -> None:
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0)
    except (OSError, AttributeError):
        pass


def _drop_fork_server_link() -> None:
    """Close this process's copy of the launcher's end of the pipe the fork server watches (a forked child gets
    one, so that it could fork more through the same server; cosim.runtime.procstart): with it closed the server
    sees the launcher die, exits, and the kernel sends this process SIGTERM (PR_SET_PDEATHSIG). Nothing to do in a
    spawned child."""
    from multiprocessing import forkserver

    server = getattr(forkserver, "_forkserver", None)
    fd = getattr(server, "_forkserver_alive_fd", None)
    if fd is not None:
        try:
            os.close(fd)
        except OSError:
            pass
        server._forkserver_alive_fd = None


def _say(slot, text: str) -> None:
    """Write ``text`` into the slot's ``activity`` (cut to its size, whole UTF-8 characters)."""
    slot["activity"] = text.encode("utf-8")[:ACTIVITY_BYTES].decode("utf-8", "ignore").encode("utf-8")


def _on_sigterm(signum, frame) -> None:
    raise SystemExit(143)


def child_main(args: ChildArgs) -> None:
    """Run one participant in this process until the last frame, a failure or a stop."""
    t_main = time.time()
    # the launcher, or the fork server it started its ring members from (cosim.runtime.procstart), which exits
    # with it: either way a new parent means the launcher is gone
    parent = os.getppid()
    keep_heap()
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _on_sigterm)
    _die_with_parent()
    _drop_fork_server_link()
    name = args.spec.name
    fd = os.open(args.log_path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
    os.dup2(fd, 1)
    os.dup2(fd, 2)
    os.close(fd)
    configure_logging(args.log_path, console=False)
    log = logging.getLogger(f"cosim.{name}")
    seg = Segment.attach(args.segment, expect=args.fingerprint)
    slot = seg.slot(name)
    slot["pid"] = os.getpid()
    slot["phase"] = Phase.STARTING
    heartbeat = Heartbeat(seg.slot_words(name)).start()
    participant = None
    code = 0

    def check() -> None:
        if os.getppid() != parent:
            raise RunError(f"{name}: the launcher (pid {args.parent_pid}) is gone", process=name,
                           frame=int(slot["frame"]))

    set_activity(lambda text: _say(slot, text))
    try:
        scenario = Scenario.model_validate_json(args.scenario_json)
        t_create = time.time()
        activity("loading its models")
        participant = args.spec.create(scenario)
        t_start = time.time()
        activity("starting")
        participant.start(seg)
        t_ready = time.time()
        log.info("started (pid %d) %.2f s after its spawn: interpreter and imports %.2f s, create %.2f s, start %.2f s",
                 os.getpid(), t_ready - args.spawned_at_s, t_main - args.spawned_at_s, t_start - t_create,
                 t_ready - t_start)
        set_activity(None)
        # no deadline on the waits: the launcher's watch judges the members' progress (cosim.runtime.liveness)
        if isinstance(args.plan, PipePlan):
            pipelined_loop(name, participant, seg, Gates(seg, args.plan, args.semaphores, name, check), args.plan,
                           startup_timeout_s=None, handoff_timeout_s=None)
        else:
            member_loop(name, participant, seg, Token(seg, args.semaphores), args.plan,
                        startup_timeout_s=None, handoff_timeout_s=None, check=check)
        log.info("finished %d frames (cpu %.2f s)", args.plan.frames + 1, time.process_time())
    except BaseException as exc:  # noqa: BLE001 - every failure must reach the launcher with its traceback
        code = 143 if isinstance(exc, SystemExit) else 1
        slot["phase"] = Phase.FAILED
        if not isinstance(exc, SystemExit):
            seg.report_error(name, int(slot["frame"]), type(exc).__name__, str(exc), traceback.format_exc())
            log.error("failed at frame %d: %s: %s", int(slot["frame"]), type(exc).__name__, exc)
    finally:
        if participant is not None:
            try:
                participant.close()
            except Exception:  # noqa: BLE001
                log.exception("close failed")
        if code == 0:
            slot["phase"] = Phase.CLOSED
        heartbeat.stop()
        seg.close()
        logging.shutdown()
        sys.stdout.flush()
        sys.stderr.flush()
    # Everything is closed and flushed. Returning would let the interpreter tear down every module the participant
    # imported (numpy, cv2, GL: 0.1-0.3 s of CPU) while the launcher waits to join this process before it writes
    # the outputs; end here instead, as a forked multiprocessing child does.
    os._exit(code)
