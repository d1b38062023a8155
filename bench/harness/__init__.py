"""The benchmark harness: named cases (``bench/cases``), interleaved rounds and medians, A/B of source trees or
settings, process-tree CPU and wall time, the machine and its load, Markdown and JSON output.

``python bench/run.py --list`` lists the cases; ``python bench/run.py CASE [CASE ...]`` measures them. Case modules
import the project's code inside their functions, never at import time: the harness imports every case module to
list them, and a worker measuring an older source tree must not fail on a name that tree lacks.
"""
from .arms import ROOT, Arm, parse_arms, sample
from .registry import CASES, Case, Context, OptionError, case, get, load_cases, parse_value
from .rounds import Sample, Stat, aggregate, alternating, paired_ratios, rotating, stat
from .session import Result, Session, run_cases

__all__ = ["CASES", "ROOT", "Arm", "Case", "Context", "OptionError", "Result", "Sample", "Session", "Stat",
           "aggregate", "alternating", "case", "get", "load_cases", "paired_ratios", "parse_arms", "parse_value",
           "rotating", "run_cases", "sample", "stat"]
