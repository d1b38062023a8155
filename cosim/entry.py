"""The command-line entry shared by ``python launch.py`` and ``python -m cosim``: imports the CLI inside a guard so
that Ctrl-C or SIGTERM while it is still importing exits 130 without a traceback, like any later moment."""
import signal
import sys

__all__ = ["run_cli"]


def run_cli() -> int:
    """Run :func:`cosim.cli.main` on ``sys.argv``; the process exit status."""
    signal.signal(signal.SIGTERM, signal.default_int_handler)
    try:
        from cosim.cli import main

        return main()
    except KeyboardInterrupt:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        sys.stderr.write("interrupted\n")
        return 130
