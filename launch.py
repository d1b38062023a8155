#!/usr/bin/env python3
"""Run a co-simulation scenario: ``python launch.py [run] [SCENARIO] [options]``; ``--help`` lists the verbs."""
import sys

from cosim.cli import main

if __name__ == "__main__":
    sys.exit(main())
