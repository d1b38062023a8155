#!/usr/bin/env python3
"""Run a co-simulation scenario: ``python launch.py [run] [SCENARIO] [options]``; ``--help`` lists the verbs."""
if __name__ == "__main__":
    # imported here, not at the top: every spawned run process re-executes this file as ``__mp_main__`` and needs
    # nothing from the command line
    from cosim.entry import exit_cli

    exit_cli()
