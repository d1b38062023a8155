"""``python -m cosim ...`` - same as ``python launch.py ...``."""
import signal
import sys

if __name__ == "__main__":
    # Ctrl-C or SIGTERM while the CLI is still importing: exit 130 without a traceback (as launch.py)
    signal.signal(signal.SIGTERM, signal.default_int_handler)
    try:
        from cosim.cli import main

        code = main()
    except KeyboardInterrupt:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        sys.stderr.write("interrupted\n")
        code = 130
    sys.exit(code)
