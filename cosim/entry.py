"""The command-line entry shared by ``python launch.py``, ``python -m cosim`` and the ``graincosim`` command: imports
the CLI inside a guard so that Ctrl-C or SIGTERM while it is still importing exits 130 without a traceback, like any
later moment up to the end of the process, and makes the three resolve modules alike (:func:`same_sys_path`).

:func:`exit_cli` ends the process itself once the CLI has returned: the interpreter's own exit resets the signal
handlers before it flushes the output and tears its modules down (~0.1 s), and a SIGTERM then killed the process
(status 143) after the summary was printed. Instead the exit handlers run (logging, multiprocessing) and the
output is flushed with the handlers still installed, then ``os._exit``: a signal at any moment until then makes
the status 130.
"""
import atexit
import os
import signal
import sys
from typing import NoReturn

__all__ = ["run_cli", "exit_cli", "same_sys_path", "package_root"]

#: exit status of a run stopped by Ctrl-C or SIGTERM (cosim.cli.EXIT_INTERRUPTED, which may not be imported yet)
EXIT_INTERRUPTED = 130


def package_root() -> str:
    """The folder holding the ``cosim`` package (a checkout's root, or site-packages)."""
    return os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def same_sys_path() -> None:
    """Replace ``sys.path[0]``, the entry's own folder (launch.py's folder, the working directory for ``python -m``,
    the scripts folder for ``graincosim``), by :func:`package_root`, so that plug-in modules (and everything else)
    are found the same way whichever entry started the run: the scenario's ``plugin_dir`` first, then the
    package's root, ``PYTHONPATH`` and site-packages; the working directory only when it is one of them."""
    if sys.path and not sys.flags.safe_path:         # python -P prepends nothing: then sys.path[0] is not ours
        sys.path[0] = package_root()
    elif package_root() not in sys.path:
        sys.path.insert(0, package_root())


#: set once the CLI has returned (or stopped): from then on a stop signal is only noted in :data:`_STOPS`
_ending = False
#: stop signals received after :data:`_ending` was set
_STOPS: list[int] = []


def _on_stop(signum, frame) -> None:
    """Ctrl-C / SIGTERM: KeyboardInterrupt while the CLI runs, a note once it has returned."""
    if _ending:
        _STOPS.append(signum)
        return
    raise KeyboardInterrupt


def run_cli() -> int:
    """Run :func:`cosim.cli.main` on ``sys.argv``; the process exit status.

    A stop signal at any moment until the status is known (even between ``main``'s return and this function
    noting it) raises KeyboardInterrupt inside the ``try`` and makes the status 130; after that it is noted in
    :data:`_STOPS` (the end of the process reads it), never raised: there is no moment at which it could escape
    as a traceback."""
    global _ending
    same_sys_path()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, _on_stop)
    try:
        try:
            # the ring members' fork server imports their common modules while the command line loads
            from cosim.runtime.procstart import prestart_for

            prestart_for(sys.argv[1:])
            from cosim.cli import main

            code = main()
        finally:
            _ending = True
    except KeyboardInterrupt:
        code = EXIT_INTERRUPTED
        sys.stderr.write("interrupted\n")
    return code


def exit_cli() -> NoReturn:
    """Run the CLI and end the process with its status (130 if a stop signal comes before the very end)."""
    code = run_cli()
    try:
        atexit._run_exitfuncs()  # what the interpreter's exit would run: logging.shutdown, multiprocessing's
    finally:
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError):  # a closed pipe, a closed stream: nothing more can be said
                pass
    os._exit(EXIT_INTERRUPTED if _STOPS else code)
