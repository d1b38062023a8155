"""The native wrapper of pythonfmu / pythonfmu3 FMUs at process exit: its interpreter handle released in order.

Every FMU built with pythonfmu (>= 0.7) or pythonfmu3 carries the same native wrapper, which keeps the interpreter
state of its instances in a namespace-scope ``std::shared_ptr`` and empties it from an
``__attribute__((destructor))`` function, ``finalizePythonInterpreter``. The wrapper's library cannot be unloaded
(it defines unique symbols), so it lives until the process exits, where glibc runs the pointer's static
destructor first (an exit handler: the state is freed) and the library's destructor after it (``_dl_fini``),
which then releases the destroyed pointer's block a second time: a use-after-free (valgrind: "Invalid read of size
4 at finalizePythonInterpreter, inside a block free'd by __run_exit_handlers") that corrupts the heap whenever the
block has been reused in between ("corrupted double-linked list", exit 134 after all work is done: 10 runs in
120 of ``tests/test_fmu_export.py`` with the mock on Embree's instanced cast, its per-frame cast or numpy alike;
none in 80 with :func:`release_at_exit`).

:func:`release_at_exit` calls ``finalizePythonInterpreter`` once more, from a Python ``atexit`` handler: those run
inside the interpreter's finalisation, before the C exit handlers, so the pointer is empty before either
destructor sees it, and both find nothing to release. Done only where the interpreter is the host's own (a Python
master such as fmpy, which started with a command line): an FMU loaded by a C host (Simulink) started the
interpreter itself, and its wrapper finalises it from that same destructor; that order is pythonfmu's to fix.
"""
from __future__ import annotations

import atexit
import ctypes
import os
import sys
from pathlib import Path

__all__ = ["FINALIZER", "binaries_of", "host_owns_interpreter", "release_at_exit"]

#: the wrapper's exported function that empties its interpreter handle
FINALIZER = "finalizePythonInterpreter"
#: binary file name endings of an FMU's platforms that have the exit order (Windows' DllMain has not)
_SUFFIXES = (".so", ".dylib")

_registered: set[str] = set()


def host_owns_interpreter() -> bool:
    """Whether this interpreter was started by the host process (it has a command line, ``sys.orig_argv``), not by
    an FMU's wrapper inside a C host (``Py_Initialize`` without one)."""
    return bool(getattr(sys, "orig_argv", None))


def binaries_of(resources: str | Path, model_identifier: str) -> list[Path]:
    """An unpacked FMU's binaries of ``model_identifier`` for every platform (``binaries/*/<id>.so``), found from
    its ``resources`` folder."""
    root = Path(resources).parent / "binaries"
    return sorted(p for s in _SUFFIXES for p in root.glob(f"*/{model_identifier}{s}"))


def _loaded(path: str):
    """The library at ``path`` if this process has it loaded (never loads it), else None."""
    try:
        return ctypes.CDLL(path, mode=os.RTLD_NOLOAD | os.RTLD_LAZY)
    except OSError:
        return None


def _release(path: str) -> None:
    lib = _loaded(path)
    if lib is not None:
        getattr(lib, FINALIZER)()


def release_at_exit(library: str | Path) -> bool:
    """Have the pythonfmu wrapper at ``library`` (a loaded FMU binary) empty its interpreter handle before the
    process's exit handlers run (once per library). True when it was registered (the library is loaded, exports
    ``finalizePythonInterpreter`` and the host owns the interpreter), False otherwise (nothing done)."""
    path = str(Path(library).resolve())
    if path in _registered:
        return True
    lib = _loaded(path)
    if lib is None or not hasattr(lib, FINALIZER) or not host_owns_interpreter():
        return False
    _registered.add(path)
    atexit.register(_release, path)
    return True
