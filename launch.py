#!/usr/bin/env python3
"""Run a co-simulation scenario: ``python launch.py [run] [SCENARIO] [options]``; ``--help`` lists the verbs."""
import sys

if __name__ == "__main__":
    import signal

    # Ctrl-C or SIGTERM while the CLI is still importing: exit 130 without a traceback, like any later moment
    signal.signal(signal.SIGTERM, signal.default_int_handler)
    try:
        # imported here, not at the top: every spawned run process re-executes this file as ``__mp_main__`` and
        # needs nothing from the command line
        from cosim.cli import main

        code = main()
    except KeyboardInterrupt:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        sys.stderr.write("interrupted\n")
        code = 130
    sys.exit(code)
