"""How a run's ring members are started: forked from a server that has already imported what they all import.

A spawned child is a fresh interpreter that imports numpy, pydantic, the scenario records, the segment and the
runtime (about 0.25 s of CPU) before it imports its own participant; a perception run starts three such children
at once on the same cores, where the ground-truth run starts one. Here the children are forked from
multiprocessing's fork server (``forkserver`` start method), which imports :data:`PRELOAD` once and forks each
child from that state: a child imports only its participant's own modules (dynamics, the renderer and moderngl,
perception and OpenCV). The server is a clean single-threaded process started by exec, not a fork of the
launcher, so nothing of the launcher (threads, locks, open files, signal handlers) leaks into a child. The
command line starts it (:func:`prestart`) before it imports itself and loads the scenario, so the two overlap;
later runs in the same process (sweeps, studies, tests) reuse it.

A child's parent is the server, which exits when the launcher does (multiprocessing closes its end of a pipe the
server watches): a child notices its parent changing (cosim.runtime.child) and is sent SIGTERM by the kernel
(PR_SET_PDEATHSIG), as with a spawned child whose launcher dies. Where the fork server is not available (not
POSIX), children are spawned.
"""
from __future__ import annotations

import multiprocessing as mp

from .signals import no_sigint_in_children
from .threadpools import single_threaded_pools

__all__ = ["PRELOAD", "RUN_VERBS", "prestart", "prestart_for", "ring_context"]

#: modules every ring member imports, imported once by the fork server
PRELOAD = ("cosim.runtime.child",)
#: command-line verbs that launch runs (the verb of ``launch.py [SCENARIO]`` is run)
RUN_VERBS = ("run", "compare", "study", "sweep")
_VERBS = RUN_VERBS + ("validate", "schema", "view", "replay", "list")


def ring_context():
    """The multiprocessing context ring members are started in: the fork server with :data:`PRELOAD`, else
    spawn."""
    if "forkserver" not in mp.get_all_start_methods():
        return mp.get_context("spawn")
    ctx = mp.get_context("forkserver")
    ctx.set_forkserver_preload(list(PRELOAD))
    return ctx


def prestart() -> None:
    """Start the fork server now, so that its imports overlap the caller's own work: in an environment whose
    numerical thread pools are single-threaded (cosim.runtime.threadpools) and with SIGINT ignored, which the
    server and every child forked from it keep (the launcher coordinates a stop). No-op where there is none."""
    ctx = ring_context()
    if ctx.get_start_method() != "forkserver":
        return
    from multiprocessing import forkserver

    with single_threaded_pools(), no_sigint_in_children():
        forkserver.ensure_running()


def prestart_for(argv: list[str]) -> None:
    """:func:`prestart` when the command line ``argv`` (without the program name) launches runs."""
    verb = argv[0] if argv and argv[0] in _VERBS else "run"
    if verb in RUN_VERBS and not any(a in ("-h", "--help") for a in argv):
        prestart()
