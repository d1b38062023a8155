"""CPU time of a whole process tree, for the benchmarks: this process becomes the subreaper of its descendants, so
a process that outlives its parent (a run's resource tracker, a fork server, a sweep worker's runs) is
reparented here and counted once reaped."""
from __future__ import annotations

import os
import resource
import time

__all__ = ["REAP_S", "become_subreaper", "reap", "tree_cpu_s"]

#: how long :func:`reap` waits for the processes that outlive their parent, s
REAP_S = 5.0
#: prctl option that makes this process the subreaper of its descendants (Linux)
_PR_SET_CHILD_SUBREAPER = 36


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
