"""The command-line entry shared by ``python launch.py``, ``python -m cosim`` and ``graincosim``: imports the CLI
inside a guard so that Ctrl-C or SIGTERM while it is still importing exits 130 without a traceback, like any later
moment, up to the end of the process.

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

__all__ = ["run_cli", "exit_cli"]

#: exit status of a run stopped by Ctrl-C or SIGTERM (cosim.cli.EXIT_INTERRUPTED, which may not be imported yet)
EXIT_INTERRUPTED = 130


def run_cli() -> int:
    """Run :func:`cosim.cli.main` on ``sys.argv``; the process exit status."""
    signal.signal(signal.SIGTERM, signal.default_int_handler)
    try:
        from cosim.cli import main

        code = main()
    except KeyboardInterrupt:
        sys.stderr.write("interrupted\n")
        code = EXIT_INTERRUPTED
    if code == EXIT_INTERRUPTED:  # the process is ending on a stop: more signals change nothing
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
    return code


def exit_cli() -> NoReturn:
    """Run the CLI and end the process with its status (130 if a stop signal comes before the very end)."""
    code = run_cli()
    stopped: list[int] = []
    for sig in (signal.SIGINT, signal.SIGTERM):
        if signal.getsignal(sig) is not signal.SIG_IGN:
            signal.signal(sig, lambda signum, frame: stopped.append(signum))
    try:
        atexit._run_exitfuncs()  # what the interpreter's exit would run: logging.shutdown, multiprocessing's
    finally:
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError):  # a closed pipe, a closed stream: nothing more can be said
                pass
    os._exit(EXIT_INTERRUPTED if stopped else code)
