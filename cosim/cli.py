"""Command line: ``python launch.py ...`` and ``python -m cosim ...`` (argparse).

Verbs: ``run [SCENARIO]`` (the default verb; no scenario runs the packaged default), ``validate SCENARIO``,
``schema`` (write the scenario JSON Schema), ``view RUN`` (attach the live viewer to a running run) and
``replay FILE.mcap`` (serve a recording to the viewer's dashboard, with play / pause / step / seek), ``report
RUN_DIR`` (draw a run's figures, a failed run's too), ``list`` (the packaged scenarios with their descriptions),
``compare``, ``study``, ``sweep`` and ``export-fmu SCENARIO --out NAME.fmu`` (the scenario's world, sensors and
perception as an FMU, docs/fmu.md). Exit codes: 0 success, 1 run failure, 2 invalid scenario or usage, 3
(``run --require-filled``, ``sweep --require-filled``) the job was not done (the outcome is not ``filled``), 130
interrupted.
"""
from __future__ import annotations

import argparse
import functools
import signal
import sys
import threading
from pathlib import Path
from typing import Callable, Sequence

from cosim.runtime.threadpools import default_to_single_threaded_pools

from .errors import OutputError, RunRefused, ScenarioError, shown_path
from .studies.commands import add_sweep_parser, out_options, study_command, sweep_command

__all__ = ["main", "build_parser", "run_extras", "required_exit", "VERBS", "PLAIN_VERBS", "SCENARIO_VERBS",
           "EXIT_NOT_FILLED"]

VERBS = ("run", "validate", "schema", "compare", "study", "view", "replay", "report", "list", "sweep",
         "export-fmu", "export")
EXIT_RUN_ERROR = 1
EXIT_SCENARIO = 2
#: ``run --require-filled``: the run completed but its outcome is not ``filled`` (summary.json ``outcome``)
EXIT_NOT_FILLED = 3
EXIT_INTERRUPTED = 130


def _scenario_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("scenario", nargs="?", default="default",
                   help="scenario YAML file, or the name of a packaged scenario (default: %(default)s)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="PATH=VALUE",
                   help="override one field, e.g. --set timing.sensor_period_s=0.05 (repeatable)")
    p.add_argument("--renderer", choices=("gl", "mock", "none"), help="renderer backend (overrides the scenario)")
    p.add_argument("--feedback", choices=("ground_truth", "perception"), help="controller feedback source")
    p.add_argument("--seed", type=int, help="random seed (overrides the scenario)")
    p.add_argument("--duration", type=float, metavar="SECONDS", help="simulated duration (overrides the scenario)")
    p.add_argument("--no-plugins", dest="allow_plugins", action="store_false",
                   help="refuse any plug-in that is not built in (a scenario that names a plug-in runs its code)")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="launch.py", description="Perception-in-the-loop grain offloading co-simulation")
    sub = parser.add_subparsers(dest="verb")
    run = sub.add_parser("run", help="run a scenario (default verb)")
    _scenario_options(run)
    out_options(run, "run directory (default runs/<scenario>-<timestamp>)", overwrite=True)
    run.add_argument("--viewer", action="store_true",
                     help="render the RGB image and serve the live dashboard on 127.0.0.1 (see --viewer-port)")
    run.add_argument("--viewer-port", type=int, default=8765, metavar="PORT",
                     help="port of the --viewer dashboard (default %(default)s; 0: any free port)")
    run.add_argument("--viewer-host", default="127.0.0.1", metavar="HOST",
                     help="address the --viewer dashboard listens on (default %(default)s, local only)")
    run.add_argument("--record", nargs="?", const=True, default=None, type=Path, metavar="FILE",
                     help="write an MCAP recording (Foxglove schemas) to FILE (default <run dir>/recording.mcap)")
    run.add_argument("--record-image-every", type=int, default=None, metavar="N",
                     help="record camera images every N frames (default 5; LiDAR, maps and scalars every frame)")
    run.add_argument("--foxglove", action="store_true",
                     help="serve the run live to Foxglove / Lichtblick over WebSocket on 127.0.0.1 (see --foxglove-port)")
    run.add_argument("--foxglove-port", type=int, default=8766, metavar="PORT",
                     help="port of the --foxglove server (default %(default)s)")
    run.add_argument("--quiet", action="store_true", help="no progress output")
    run.add_argument("--require-filled", action="store_true",
                     help="exit 3 when the run completed but did not fill the cart (outcome stopped_safe, "
                     "unfinished or job_failed in summary.json)")
    val = sub.add_parser("validate", help="validate a scenario and print the resolved result")
    _scenario_options(val)
    val.add_argument("--print", action="store_true", help="print the fully resolved scenario as YAML")
    cmp_ = sub.add_parser("compare", help="run with ground-truth and with perception feedback; write one report")
    _scenario_options(cmp_)
    out_options(cmp_, "report directory, a run directory per variant inside (default "
                "runs/compare-<scenario>-<timestamp>)", overwrite=True)
    cmp_.add_argument("--quiet", action="store_true", help="no progress output")
    st = sub.add_parser("study", help="error against run time over the fidelity knobs")
    _scenario_options(st)
    st.add_argument("--knobs", default="dynamics,grain_cell", help="comma-separated: dynamics, grain_cell, render, "
                    "beams, perception_grid (default: %(default)s)")
    st.add_argument("--sim-seconds", type=float, default=20.0, help="simulated seconds per setting")
    out_options(st, "output directory (default runs/study-<scenario>-<timestamp>; run again to resume)")
    st.add_argument("--quiet", action="store_true", help="no progress output")
    st.add_argument("--knob", action="append", default=[], metavar="NAME=PATH:V1,V2",
                    help="a knob of your own: one field over values, the last the reference (repeatable)")
    st.add_argument("--jobs", type=int, default=1, metavar="N", help="runs at once (default 1: timings stay "
                    "comparable)")
    st.add_argument("--scheduler", metavar="ADDRESS", help="run on an existing Dask cluster")
    add_sweep_parser(sub)
    sch = sub.add_parser("schema", help="write the scenario JSON Schema")
    sch.add_argument("--out", type=Path, help="output file (default: stdout)")
    view = sub.add_parser("view", help="attach the live viewer to a running run (python -m cosim.viewer --attach)")
    view.add_argument("run", help="run directory (with run.json) or shared-memory segment name")
    _server_options(view)
    rpl = sub.add_parser("replay", help="serve an MCAP recording to the viewer's dashboard (play, pause, step, seek)")
    rpl.add_argument("file", type=Path, help="recording written by run --record")
    _server_options(rpl)
    rpl.add_argument("--speed", type=float, default=1.0, help="x simulated time (default %(default)s)")
    rpl.add_argument("--loop", action="store_true", help="start over at the end")
    rep = sub.add_parser("report", help="draw a run directory's figures (a failed or stopped run's too)")
    rep.add_argument("run_dir", type=Path, help="run directory")
    sub.add_parser("list", help="list the packaged scenarios (run them by name) with their descriptions")
    exp = sub.add_parser("export-fmu", aliases=["export"], help="write the scenario's world, sensors and perception as a co-simulation "
                         "FMU (docs/fmu.md)")
    _scenario_options(exp)
    exp.add_argument("--out", type=Path, required=True, metavar="NAME.fmu", help="the FMU file to write (an "
                     "existing folder: <scenario name>.fmu in it)")
    exp.add_argument("--overwrite", action="store_true", help="replace an FMU already at --out")
    exp.add_argument("--parents", action="store_true", help="create --out's missing folders")
    exp.add_argument("--fmi", choices=("2", "3"), default="2", help="FMI version (default %(default)s; 3 needs "
                     "pythonfmu3)")
    return parser


def _server_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--port", type=int, default=8765, help="dashboard port (default %(default)s; 0: any free port)")
    p.add_argument("--host", default="127.0.0.1", help="address to listen on (default %(default)s, local only)")


def run_extras(args: argparse.Namespace, scenario=None) -> tuple[list, list]:
    """(observers, sinks) that ``run``'s --viewer, --foxglove and --record ask for (``scenario``: the cart's size
    for the dashboard's metre axes; the scenario --foxglove serves). ValueError (exit 2, nothing started) for a
    --foxglove-port in use."""
    observers, sinks = [], []
    if getattr(args, "foxglove", False):
        from cosim.runtime.launcher import ObserverSpec

        from .foxglove.live import DEFAULT_HOST
        from .viewer.address import PortBusy, check_port

        if scenario is None:
            raise TypeError("run_extras: --foxglove needs the loaded scenario")
        if getattr(args, "viewer", False) and args.viewer_port == args.foxglove_port != 0:
            raise ValueError(f"--foxglove-port {args.foxglove_port} is the dashboard's port too (--viewer-port); "
                             "choose another (nothing was started)")
        try:
            check_port(DEFAULT_HOST, args.foxglove_port)
        except PortBusy:
            raise ValueError(f"--foxglove-port {args.foxglove_port}: {DEFAULT_HOST}:{args.foxglove_port} is already "
                             "in use; choose another port (nothing was started)") from None
        observers.append(ObserverSpec("foxglove", "cosim.foxglove.live:observe",
                                      {"port": args.foxglove_port, "scenario_json": scenario.model_dump_json()}))
    if getattr(args, "viewer", False):
        from cosim.runtime.launcher import ObserverSpec
        from cosim.viewer.viewinfo import ViewInfo

        observers.append(ObserverSpec("viewer", "cosim.viewer.server:observe",
                                      {"port": args.viewer_port, "host": args.viewer_host,
                                       "announce": getattr(args, "viewer_announce", None),
                                       "view": None if scenario is None else ViewInfo.of(scenario).to_dict()}))
    if getattr(args, "record", None) is not None:
        from .recording import RecordOptions, mcap_sink

        path = None if args.record is True else args.record
        every = {} if args.record_image_every is None else {"image_every": args.record_image_every}
        sinks.append(mcap_sink(RecordOptions(path=path, **every)))
    return observers, sinks


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
    from cosim.scenario.loader import load_scenario, resolve_scenario_arg

    path = resolve_scenario_arg(args.scenario)
    return load_scenario(path, args.overrides, extra=_extra(args), allow_plugins=args.allow_plugins)


def _print_summary(result, stream) -> None:
    s = result.summary
    lines = [f"run directory: {shown_path(result.run_dir)}",
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
    figures = s.get("figures") or {}
    if figures.get("status") == "not_drawn":
        lines.append(f"figures: not drawn ({figures['reason']}); to draw them: {figures['command']}")
    elif figures.get("status") == "failed":
        lines.append(f"figures: failed: {figures['error']}")
    if result.error is not None:
        lines.append(f"error: {result.error}")
    from .runtime.outcome import outcome_line

    lines.append(outcome_line(s.get("outcome")))
    stream.write("\n".join(lines) + "\n")


def _report(run_dir: Path) -> int:
    """``report RUN_DIR``: draw the run's figures and record them in its summary.json."""
    from cosim.runtime.figures import report

    try:
        entry = report(run_dir)
    except (FileNotFoundError, ValueError) as exc:
        sys.stderr.write(f"{exc}\n")
        return EXIT_SCENARIO
    except OutputError as exc:
        sys.stderr.write(f"{exc}\n")
        return EXIT_RUN_ERROR
    sys.stdout.write(f"figures of {run_dir}: {', '.join(entry['files'])}\n")
    return 0


def _interruptible(fn):
    """``main`` ends with exit 130 and one line, no traceback, on Ctrl-C or SIGTERM at any moment (a run handles
    them itself: cosim.runtime.signals; this covers the start-up before it and the printing after it), and with
    exit 2 and the reason when a run is refused before it starts (cosim.errors.RunRefused)."""

    def term(signum, frame):
        raise KeyboardInterrupt

    @functools.wraps(fn)
    def wrapper(argv: Sequence[str] | None = None) -> int:
        main_thread = threading.current_thread() is threading.main_thread()
        old = signal.signal(signal.SIGTERM, term) if main_thread else None
        code = EXIT_INTERRUPTED
        try:
            code = fn(argv)
        except RunRefused as exc:  # --out unusable or locked, the segment would not fit: before anything started
            sys.stderr.write(f"{exc}\nnothing was started.\n")
            code = EXIT_SCENARIO
        except KeyboardInterrupt:
            sys.stderr.write("interrupted\n")
        finally:
            if main_thread:  # main is also called in-process (tests, scripts): leave the handlers as found
                signal.signal(signal.SIGTERM, old)
        return code

    return wrapper


def _view(args: argparse.Namespace) -> int:
    """``view`` and ``replay``: the dashboard attached to a live run or replaying a recording."""
    from .viewer.__main__ import main as viewer_main

    where = ["--port", str(args.port), "--host", args.host]
    if args.verb == "view":
        return viewer_main(["--attach", args.run, *where])
    return viewer_main(["--replay", str(args.file), *where, "--speed", str(args.speed)]
                       + (["--loop"] if args.loop else []))


def _list(args: argparse.Namespace) -> int:
    """``list``: the packaged scenarios, one line each."""
    from cosim.scenario.loader import describe_packaged

    rows = describe_packaged()
    width = max(len(n) for n in rows)
    sys.stdout.write("".join(f"{n:<{width}}  {d}\n" for n, d in rows.items()))
    return 0


def _schema(args: argparse.Namespace) -> int:
    """``schema``: the scenario's JSON Schema, to ``--out`` or stdout."""
    from cosim.scenario.jsonschema import schema_text

    text = schema_text()
    if args.out:
        args.out.write_text(text)
    else:
        sys.stdout.write(text)
    return 0


def _validate(args: argparse.Namespace, scenario) -> int:
    """``validate``: the resolved scenario (``--print``) or what it loads."""
    if args.print:
        from cosim.scenario.loader import dump_resolved

        sys.stdout.write(dump_resolved(scenario))
    else:
        from cosim.scenario.trust import format_inventory, inspect_scenario

        sys.stdout.write(f"{args.scenario}: valid ({scenario.frames + 1} frames, ring "
                         f"{' -> '.join(scenario.participants)})\nloads (a plug-in runs its code):\n"
                         f"{format_inventory(inspect_scenario(scenario, versions=True)[0])}\n")
    return 0


def _export(args: argparse.Namespace, scenario) -> int:
    """``export-fmu`` (``export``): the scenario's world as an FMU."""
    from cosim.fmi.export.build import export_command

    return export_command(args, scenario)


def _compare(args: argparse.Namespace, scenario) -> int:
    """``compare``: the scenario with ground-truth and with perception feedback, and the report."""
    from cosim.runtime.outputs import default_run_dir
    from cosim.studies.compare import compare

    out = args.out or default_run_dir(scenario.model_copy(update={"name": f"compare-{scenario.name}"}))
    report = compare(scenario, out, quiet=args.quiet, overwrite=args.overwrite,
                     parents=args.parents or args.out is None)
    sys.stdout.write(f"report: {report}\n")
    return 0


def _run(args: argparse.Namespace, scenario) -> int:
    """``run``: one run over OS processes, its summary, and its exit status."""
    from cosim.runtime.launcher import launch
    from cosim.runtime.progress import run_progress

    progress = run_progress(scenario.name, args.quiet)
    announcer = None
    if args.viewer:
        from cosim.viewer.address import PortBusy, ViewerAnnouncer, check_port

        try:
            check_port(args.viewer_host, args.viewer_port)
        except PortBusy as exc:
            sys.stderr.write(f"{exc}; nothing was started (choose another with --viewer-port, or 0 for any)\n")
            return EXIT_SCENARIO
        announcer = ViewerAnnouncer(sys.stderr)
        args.viewer_announce = str(announcer.path)
    try:
        observers, sinks = run_extras(args, scenario)
    except ValueError as exc:
        sys.stderr.write(f"{exc}\n")
        return EXIT_SCENARIO
    try:
        result = launch(scenario, args.out, progress=progress, observers=observers, sinks=sinks,
                        overwrite=args.overwrite, parents=args.parents)
    finally:
        if announcer is not None:
            announcer.close()
        if progress is not None:
            progress.close()
    _print_summary(result, sys.stdout)
    return required_exit(result.exit_code, result.summary, args.require_filled)


#: verbs that need no scenario: verb -> handler(args) -> exit status
PLAIN_VERBS: dict[str, Callable[[argparse.Namespace], int]] = {
    "view": _view, "replay": _view, "sweep": lambda args: sweep_command(args),
    "report": lambda args: _report(args.run_dir), "list": _list, "schema": _schema,
}
#: verbs on a loaded scenario: verb -> handler(args, scenario) -> exit status
SCENARIO_VERBS: dict[str, Callable[[argparse.Namespace, object], int]] = {
    "validate": _validate, "study": lambda args, scenario: study_command(args, scenario), "export-fmu": _export,
    "export": _export, "compare": _compare, "run": _run,
}


@_interruptible
def main(argv: Sequence[str] | None = None) -> int:
    """The command line (``launch.py VERB ...``): a verb of :data:`PLAIN_VERBS` or :data:`SCENARIO_VERBS` (``run``
    when the first argument is none), its exit status."""
    default_to_single_threaded_pools()  # before numpy loads: in-process runs (study, compare) and children
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or (argv[0] not in VERBS and argv[0] not in ("-h", "--help")):
        argv.insert(0, "run")
    args = build_parser().parse_args(argv)
    if args.verb in PLAIN_VERBS:
        return PLAIN_VERBS[args.verb](args)
    try:
        scenario = _load(args)
    except ScenarioError as exc:
        sys.stderr.write(f"{exc}\n{len(exc.problems)} problem(s); nothing was started.\n")
        return EXIT_SCENARIO
    except FileNotFoundError as exc:
        sys.stderr.write(f"{exc}\n")
        return EXIT_SCENARIO
    return SCENARIO_VERBS[args.verb](args, scenario)


def required_exit(code: int, summary: dict, require_filled: bool) -> int:
    """The exit status of ``run``: the run's own (0, 1, 130), or EXIT_NOT_FILLED when it completed (0) with
    ``--require-filled`` and an outcome other than ``filled``."""
    from .runtime.outcome import FILLED

    if code == 0 and require_filled and (summary.get("outcome") or {}).get("status") != FILLED:
        return EXIT_NOT_FILLED
    return code
