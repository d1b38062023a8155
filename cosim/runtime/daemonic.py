"""Let ``launch()`` start its children from a daemonic process (a Dask worker, a multiprocessing.Pool worker).

multiprocessing refuses ``Process.start()`` in a daemonic process ("daemonic processes are not allowed to have
children") because a daemonic process may be ended without joining its children, which would leave them
orphaned. A run's launcher never relies on that: it stops, joins and (failing that) kills every child it started
before ``launch()`` returns (cosim.runtime.teardown), and each child also asks the kernel for SIGTERM when
its launcher dies (``child._die_with_parent``, PR_SET_PDEATHSIG), so even a worker killed outright leaves none
behind. :func:`children_allowed` therefore lifts the flag only for the ``start()`` calls it wraps.

Chosen over running each sweep run in a subprocess: a fresh interpreter costs about a second of imports per
run, 20-30 % of a 60 s ground-truth run's wall time on the 2-core VM, against nothing here.
"""
from __future__ import annotations

import multiprocessing as mp
import threading
from contextlib import contextmanager
from typing import Iterator

__all__ = ["children_allowed"]

_lock = threading.Lock()
_depth = 0      # threads inside children_allowed (Dask runs tasks on threads of one process)
_saved = False  # the process's daemon flag before the first of them entered


@contextmanager
def children_allowed() -> Iterator[None]:
    """Within the block, this process may start children even if it is daemonic; the flag is restored after.

    Reentrant and thread-safe: the flag is lifted by the first thread in and restored by the last one out.
    """
    global _depth, _saved
    config = mp.current_process()._config  # noqa: SLF001 - the flag Process.start() checks
    with _lock:
        if _depth == 0:
            _saved = bool(config.get("daemon", False))
            config["daemon"] = False
        _depth += 1
    try:
        yield
    finally:
        with _lock:
            _depth -= 1
            if _depth == 0 and _saved:
                config["daemon"] = True
