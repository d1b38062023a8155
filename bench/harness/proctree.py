"""CPU time of processes for the benchmarks: a whole process tree (this process becomes the subreaper of its
descendants, so a process that outlives its parent, such as a run's resource tracker, a fork server or a sweep
worker's runs, is reparented here and counted once reaped), and one live process read from ``/proc``."""
from __future__ import annotations

import os
import resource
import time

__all__ = ["REAP_S", "become_subreaper", "process_cpu_s", "reap", "self_and_tree_cpu_s", "tree_cpu_s"]

#: how long :func:`reap` waits for the processes that outlive their parent, s
REAP_S = 5.0
#: prctl option that makes this process the subreaper of its descendants (Linux)
_PR_SET_CHILD_SUBREAPER = 36
#: seconds per clock tick of /proc/<pid>/stat's CPU fields
_TICK_S = 1.0 / os.sysconf("SC_CLK_TCK")


def become_subreaper() -> bool:
    """Make this process the subreaper of its descendants (Linux); False where it cannot."""
    try:
        import ctypes

        return ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def reap(timeout_s: float = REAP_S) -> None:
    """Wait for every child that has ended or ends within ``timeout_s`` (orphans reparented here included); a
    child still running after that is left alone."""
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            pid, _ = os.waitpid(-1, os.WNOHANG)
        except ChildProcessError:
            return
        if pid == 0:
            if time.monotonic() > deadline:
                return
            time.sleep(0.01)


def tree_cpu_s() -> float:
    """CPU time (user + system, s) of every child this process has reaped so far, and of their reaped children."""
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def self_and_tree_cpu_s() -> float:
    """CPU time (s) of this process and of its reaped descendants, after reaping the ones that have ended (a
    measurement that runs work in this process and in children, e.g. a sweep's embedded cluster)."""
    reap()
    me = resource.getrusage(resource.RUSAGE_SELF)
    return me.ru_utime + me.ru_stime + tree_cpu_s()


def process_cpu_s(pid: int) -> float | None:
    """User + system CPU of the live process ``pid`` so far, s (None once it has gone)."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            fields = f.read().rsplit(b")", 1)[1].split()
    except OSError:
        return None
    return (int(fields[11]) + int(fields[12])) * _TICK_S             # utime, stime (fields 14, 15)
