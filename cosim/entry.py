"""The command-line entry shared by ``python launch.py`` and ``python -m cosim``: imports the CLI inside a guard so
that Ctrl-C or SIGTERM while it is still importing exits 130 without a traceback, like any later moment."""
import signal
import sys

__all__ = ["run_cli"]

#: exit status of a run stopped by Ctrl-C or SIGTERM (cosim.cli.EXIT_INTERRUPTED, which may not be imported yet)
EXIT_INTERRUPTED = 130


def run_cli() -> int:
    """Run :func:`cosim.cli.main` on ``sys.argv``; the process exit status."""
    signal.signal(signal.SIGTERM, signal.default_int_handler)
    try:
        # the ring members' fork server imports their common modules while the command line loads
        from cosim.runtime.procstart import prestart_for

        prestart_for(sys.argv[1:])
        from cosim.cli import main

        code = main()
    except KeyboardInterrupt:
        sys.stderr.write("interrupted\n")
        code = EXIT_INTERRUPTED
    if code == EXIT_INTERRUPTED:  # the process is ending on a stop: more signals change nothing
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
    return code
