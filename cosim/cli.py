"""Command line: ``python launch.py ...`` and ``python -m cosim ...`` (argparse).

Verbs: ``run [SCENARIO]`` (the default verb; no scenario runs the packaged default), ``validate SCENARIO``,
``schema`` (write the scenario JSON Schema). Exit codes: 0 success, 1 run failure, 2 invalid scenario or usage,
130 interrupted.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Sequence

from .errors import ScenarioError

__all__ = ["main", "build_parser", "VERBS"]

VERBS = ("run", "validate", "schema", "compare")
EXIT_SCENARIO = 2


def _scenario_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("scenario", nargs="?", default="default",
                   help="scenario YAML file, or the name of a packaged scenario (default: %(default)s)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="PATH=VALUE",
                   help="override one field, e.g. --set timing.sensor_period_s=0.05 (repeatable)")
    p.add_argument("--renderer", choices=("gl", "mock", "none"), help="renderer backend (overrides the scenario)")
    p.add_argument("--feedback", choices=("ground_truth", "perception"), help="controller feedback source")
    p.add_argument("--seed", type=int, help="random seed (overrides the scenario)")
    p.add_argument("--duration", type=float, metavar="SECONDS", help="simulated duration (overrides the scenario)")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="launch.py", description="Perception-in-the-loop grain offloading co-simulation")
    sub = parser.add_subparsers(dest="verb")
    run = sub.add_parser("run", help="run a scenario (default verb)")
    _scenario_options(run)
    run.add_argument("--out", type=Path, help="run directory (default runs/<scenario>-<timestamp>)")
    run.add_argument("--viewer", action="store_true", help="allocate the viewer's blocks (RGB) for an observer")
    run.add_argument("--quiet", action="store_true", help="no progress output")
    val = sub.add_parser("validate", help="validate a scenario and print the resolved result")
    _scenario_options(val)
    val.add_argument("--print", action="store_true", help="print the fully resolved scenario as YAML")
    cmp_ = sub.add_parser("compare", help="run with ground-truth and with perception feedback; write one report")
    _scenario_options(cmp_)
    cmp_.add_argument("--out", type=Path, help="report directory (default runs/compare-<scenario>-<timestamp>)")
    cmp_.add_argument("--quiet", action="store_true", help="no progress output")
    sch = sub.add_parser("schema", help="write the scenario JSON Schema")
    sch.add_argument("--out", type=Path, help="output file (default: stdout)")
    return parser


def _extra(args: argparse.Namespace) -> dict:
    extra = {}
    if args.renderer is not None:
        extra["renderer"] = args.renderer
    if args.feedback is not None:
        extra["feedback"] = args.feedback
    if args.seed is not None:
        extra["seed"] = args.seed
    if args.duration is not None:
        extra["duration_s"] = args.duration
    if getattr(args, "viewer", False):
        extra["viewer"] = True
    return extra


def _load(args: argparse.Namespace):
    from .loader import load_scenario, resolve_scenario_arg

    path = resolve_scenario_arg(args.scenario)
    return load_scenario(path, args.overrides, extra=_extra(args))


def _print_summary(result, stream) -> None:
    s = result.summary
    lines = [f"run directory: {result.run_dir}",
             f"completed: {s.get('completed')}  frames: {s.get('frames')}  sim {s.get('sim_time_s', 0):.1f} s  "
             f"wall {s.get('wall_time_s', 0):.1f} s  real-time factor {s.get('real_time_factor') or 0:.1f}x"]
    fill = s.get("fill")
    if fill:
        lines.append(f"fill: {fill.get('fill_fraction', 0) * 100:.1f} %  max overfill "
                     f"{(fill.get('max_overfill_m') or 0) * 100:.1f} cm  profile RMSE "
                     f"{(fill.get('profile_rmse_m') or 0) * 100:.1f} cm")
    if s.get("spill"):
        lines.append(f"spill: {s['spill'].get('mass_kg', 0):.1f} kg")
    if s.get("timing_ms"):
        lines.append("per-frame medians (ms): " + ", ".join(f"{k} {v:.2f}" for k, v in s["timing_ms"].items()
                                                            if v is not None))
    if result.error is not None:
        lines.append(f"error: {result.error}")
    stream.write("\n".join(lines) + "\n")


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or (argv[0] not in VERBS and argv[0] not in ("-h", "--help")):
        argv.insert(0, "run")
    args = build_parser().parse_args(argv)
    if args.verb == "schema":
        from .jsonschema import schema_text

        text = schema_text()
        if args.out:
            args.out.write_text(text)
        else:
            sys.stdout.write(text)
        return 0
    try:
        scenario = _load(args)
    except ScenarioError as exc:
        sys.stderr.write(f"{exc}\n{len(exc.problems)} problem(s); nothing was started.\n")
        return EXIT_SCENARIO
    except FileNotFoundError as exc:
        sys.stderr.write(f"{exc}\n")
        return EXIT_SCENARIO
    if args.verb == "validate":
        if args.print:
            from .loader import dump_resolved

            sys.stdout.write(dump_resolved(scenario))
        else:
            sys.stdout.write(f"{args.scenario}: valid ({scenario.frames + 1} frames, ring "
                             f"{' -> '.join(scenario.participants)})\n")
        return 0
    from .progress import ProgressPrinter

    if args.verb == "compare":
        from .compare import compare
        from .outputs import default_run_dir

        out = args.out or default_run_dir(scenario.model_copy(update={"name": f"compare-{scenario.name}"}))
        report = compare(scenario, out, None if args.quiet else ProgressPrinter())
        sys.stdout.write(f"report: {report}\n")
        return 0
    from .launcher import launch

    progress = None if args.quiet else ProgressPrinter()
    result = launch(scenario, args.out, progress=progress)
    _print_summary(result, sys.stdout)
    return result.exit_code
