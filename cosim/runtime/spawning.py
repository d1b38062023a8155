"""Starting a run's processes (ring children, observers, the recorder): one way, whatever starts them.

:func:`start_process` starts a fresh process (spawned, or forked from the fork server of
cosim.runtime.procstart: no GL or thread state of the launcher inherited), with the numeric libraries' thread
pools single-threaded (cosim.runtime.threadpools), SIGINT ignored from the first instruction
(cosim.runtime.signals), from a daemonic process too (a Dask or multiprocessing pool worker:
cosim.runtime.daemonic), and without running the user's script again.

multiprocessing runs the parent's main script again in each spawned child and in the fork server and each child
it forks (as ``__mp_main__``) so that what the script defines can be unpickled there. The targets started here
live in the package, so a script that calls ``cosim.run(...)`` or ``launch(...)`` without an ``if __name__ ==
"__main__":`` guard would run again inside each child, which dies trying to start processes of its own.
:func:`start_process` leaves the main script out of what the child (and a fork server it starts) prepares,
unless the process's arguments name something of ``__main__`` (an import path ``"__main__:fn"``, an object
defined in the script): then the script is needed there, and so is its guard.
"""
from __future__ import annotations

import contextlib
import dataclasses
import multiprocessing as mp
import threading
from contextlib import contextmanager
from multiprocessing import spawn
from typing import Callable, Iterator, Mapping

from .daemonic import children_allowed
from .signals import no_sigint_in_children
from .threadpools import single_threaded_pools

__all__ = ["start_process", "names_main"]

MAIN = "__main__"
#: how deep :func:`names_main` looks into nested arguments
_DEPTH = 6
#: the keys of multiprocessing's preparation data that make a child run the parent's main script
_MAIN_KEYS = ("init_main_from_path", "init_main_from_name")
_PREPARING = threading.Lock()


def names_main(obj, depth: int = _DEPTH) -> bool:
    """Whether ``obj`` (a process's arguments) refers to something of ``__main__``: a text naming it, a function
    or class defined there, or an instance of one, looked for through containers and dataclasses."""
    if isinstance(obj, str):
        return MAIN in obj
    if isinstance(obj, (bytes, bytearray, memoryview, int, float, bool, type(None))):
        return False
    if getattr(obj, "__module__", None) == MAIN or type(obj).__module__ == MAIN:
        return True
    if depth <= 0:
        return False
    if isinstance(obj, Mapping):
        return any(names_main(k, depth - 1) or names_main(v, depth - 1) for k, v in obj.items())
    if isinstance(obj, (list, tuple, set, frozenset)):
        return any(names_main(v, depth - 1) for v in obj)
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return any(names_main(getattr(obj, f.name), depth - 1) for f in dataclasses.fields(obj))
    return False


@contextmanager
def _without_main_script() -> Iterator[None]:
    """Processes started inside do not run the parent's main script (module docstring)."""
    with _PREPARING:
        original = spawn.get_preparation_data

        def prepare(name):
            data = original(name)
            for key in _MAIN_KEYS:
                data.pop(key, None)
            return data

        spawn.get_preparation_data = prepare
        try:
            yield
        finally:
            spawn.get_preparation_data = original


def start_process(target: Callable, args: tuple, *, name: str, daemon: bool = True,
                  ctx: mp.context.BaseContext | None = None) -> mp.process.BaseProcess:
    """Start ``target(*args)`` as process ``name`` in ``ctx`` (default: spawn; see the module docstring); returns
    it."""
    proc = (ctx or mp.get_context("spawn")).Process(target=target, args=args, name=name, daemon=daemon)
    script = contextlib.nullcontext() if names_main(args) else _without_main_script()
    with single_threaded_pools(), no_sigint_in_children(), children_allowed(), script:
        proc.start()
    return proc
