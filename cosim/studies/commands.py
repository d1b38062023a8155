"""The ``sweep`` and ``study`` verbs of the command line (cosim/cli.py parses, these run)."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from cosim.errors import ScenarioError

__all__ = ["add_sweep_parser", "out_options", "sweep_command", "study_command", "EXIT_OK", "EXIT_FAILED", "EXIT_USAGE",
           "EXIT_INTERRUPTED", "EXIT_NOT_FILLED"]

EXIT_OK, EXIT_FAILED, EXIT_USAGE, EXIT_INTERRUPTED = 0, 1, 2, 130
#: ``sweep --require-filled``: every run completed, but not every one filled the cart
EXIT_NOT_FILLED = 3


def out_options(p: argparse.ArgumentParser, what: str, *, overwrite: bool = False) -> None:
    """``--out DIR`` and ``--parents`` (and ``--overwrite``): the rules of cosim.runtime.rundir."""
    p.add_argument("--out", type=Path, help=f"{what}; only its last folder is created (see --parents)")
    p.add_argument("--parents", action="store_true", help="create the missing parent folders of --out too")
    if overwrite:
        p.add_argument("--overwrite", action="store_true", help="replace the files of an earlier run in --out (it is "
                       "refused without; files that are not a run's are never touched)")


def add_sweep_parser(sub) -> None:
    sw = sub.add_parser("sweep", help="run a sweep file: many runs over parameters and seeds on Dask")
    sw.add_argument("file", type=Path, help="sweep file (YAML, docs/sweeps.md)")
    sw.add_argument("--jobs", type=int, metavar="N", help="local worker processes (default: from the cores and "
                    "the processes each run needs)")
    sw.add_argument("--scheduler", metavar="ADDRESS", help="run on an existing Dask cluster, e.g. "
                    "tcp://10.0.0.5:8786 (workers need graincosim installed; GL runs need --resources EGL=1)")
    out_options(sw, "sweep directory (default runs/sweep-<name>; run again to resume)")
    sw.add_argument("--quiet", action="store_true", help="no progress bar")
    sw.add_argument("--require-filled", action="store_true",
                    help="exit 3 when every run completed but some did not fill the cart (outcome column)")


def _report(outcome, out: Path, require_filled: bool = False) -> int:
    jobs = ", ".join(f"{n} {status}" for status, n in outcome.outcomes.items()) or "none"
    sys.stdout.write(f"sweep {out}: {outcome.completed}/{outcome.total} runs completed, {outcome.failed} failed, "
                     f"{outcome.skipped} finished before; outcomes: {jobs}; results: {outcome.results}\n")
    if outcome.interrupted:
        sys.stderr.write("interrupted: the runs that finished are kept; run the same command to resume\n")
        return EXIT_INTERRUPTED
    if outcome.completed != outcome.total:
        return EXIT_FAILED
    if require_filled and outcome.outcomes.get("filled", 0) != outcome.total:
        return EXIT_NOT_FILLED
    return EXIT_OK


def _missing_engine() -> bool:
    """Whether Dask distributed or tqdm is missing from this environment (then say how to install it)."""
    try:
        import distributed  # noqa: F401
        import tqdm  # noqa: F401
    except ImportError as exc:
        sys.stderr.write(f"sweeps and studies run on Dask: {exc}; install it with pip install "
                         "'distributed>=2024.1' tqdm (dependencies of graincosim)\n")
        return True
    return False


def _problems(exc: ScenarioError) -> int:
    sys.stderr.write(f"{exc}\n{len(exc.problems)} problem(s); nothing was started.\n")
    return EXIT_USAGE


def sweep_command(args: argparse.Namespace) -> int:
    from .sweep import run_sweep
    from .sweepfile import load_sweep

    if args.jobs is not None and args.jobs < 1:
        sys.stderr.write("--jobs must be at least 1\n")
        return EXIT_USAGE
    if _missing_engine():
        return EXIT_USAGE
    try:
        sweep = load_sweep(args.file)
    except ScenarioError as exc:
        return _problems(exc)
    out = args.out or Path("runs") / f"sweep-{sweep.name}"
    sys.stderr.write(f"sweep {sweep.name}: {len(sweep.runs)} runs into {out}\n")
    try:
        outcome = run_sweep(sweep, out, scheduler=args.scheduler, jobs=args.jobs, quiet=args.quiet,
                            parents=args.parents or args.out is None)
    except RuntimeError as exc:
        sys.stderr.write(f"{exc}\n")
        return EXIT_USAGE
    except KeyboardInterrupt:  # a second Ctrl-C while the cluster closes
        sys.stderr.write(f"interrupted: the runs that finished are in {out}; run the same command to resume\n")
        return EXIT_INTERRUPTED
    return _report(outcome, out, args.require_filled)


def study_command(args: argparse.Namespace, scenario) -> int:
    from cosim.runtime.outputs import default_run_dir

    from .study import KNOBS, parse_knob, run_study

    if _missing_engine():
        return EXIT_USAGE
    names = [k.strip() for k in args.knobs.split(",") if k.strip()]
    unknown = [k for k in names if k not in KNOBS]
    if unknown:
        sys.stderr.write(f"unknown knobs {unknown}; choose from {sorted(KNOBS)}\n")
        return EXIT_USAGE
    try:
        knobs = names + [parse_knob(text, i) for i, text in enumerate(args.knob, start=1)]
        out = args.out or default_run_dir(scenario.model_copy(update={"name": f"study-{scenario.name}"}))
        md = run_study(scenario, knobs, out, args.sim_seconds, jobs=args.jobs, scheduler=args.scheduler,
                       quiet=args.quiet, parents=args.parents or args.out is None)
    except ScenarioError as exc:
        return _problems(exc)
    sys.stdout.write(md.read_text() + f"\nstudy written to {out}\n")
    return EXIT_OK
