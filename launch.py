#!/usr/bin/env python3
"""Run a co-simulation scenario: ``python launch.py [run] [SCENARIO] [options]``; ``--help`` lists the verbs."""
import sys

if __name__ == "__main__":
    # imported here, not at the top: every spawned run process re-executes this file as ``__mp_main__`` and needs
    # nothing from the command line
    from cosim.entry import run_cli

    sys.exit(run_cli())
