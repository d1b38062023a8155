"""``python -m cosim ...`` - same as ``python launch.py ...``."""
import sys

if __name__ == "__main__":
    from cosim.entry import run_cli

    sys.exit(run_cli())
