"""Instructions of start-up and shut-down, step by step (callgrind, deterministic).

Each step is a ``python -c`` snippet run from a source tree (default this checkout, ``--src`` another one, e.g.
an export of main) under ``valgrind --tool=callgrind``, after a native run that leaves every module's bytecode
cached. A step that adds to another is printed with the increment:

* the bare interpreter;
* launcher: command line, scenario loading and validation, the launcher's modules, the resolved scenario and
  the schema (every ring member's blocks): everything before it spawns the children;
* child: what a spawned participant process imports before ``child_main`` runs, then each participant's
  module and ``create`` (what ``start`` does, e.g. the renderer's GL context and shaders, is not counted); ring
  members are forked from a fork server that has imported the first part already (cosim.runtime.procstart), so
  a launched child pays only the participant's part; a spawned one (where there is no fork server) pays both;
* end of run: the plotting modules, and the four figures of a 300-frame ground-truth run (from memory; a tree
  without ``cosim.runtime.outputs.run_data`` writes the run directory's data and reads it back, as its launcher did).

Usage: ``python bench/startup_instructions.py [--src TREE] [--only NAME ...]``; several minutes (matplotlib under
valgrind). Prints one Markdown row per step: instructions (M) and the increment over the step it adds to.
"""
from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

_LOAD = ("from cosim.scenario.loader import load_scenario, resolve_scenario_arg; "
         "s = load_scenario(resolve_scenario_arg('default'))")
#: a spawned child runs the launcher's main file as __mp_main__, unpickles its arguments (cosim.runtime.child) and validates
#: the scenario's JSON ({json}: a file holding the default scenario's)
_CHILD = ("import runpy; runpy.run_path('launch.py', run_name='__mp_main__'); import multiprocessing.spawn, "
          "cosim.runtime.child; from cosim.scenario.config import Scenario; s = Scenario.model_validate_json(open('{json}').read())")
_GT = ("from cosim.scenario.loader import load_scenario, resolve_scenario_arg; "
       "s = load_scenario(resolve_scenario_arg('default'), extra={'feedback': 'ground_truth', 'renderer': 'none'})")
_FIG_DATA = (_GT + "; from cosim.runtime.inprocess import simulate; r = simulate(s, frames=300); "
             "from cosim.runtime.outputs import compose_summary; import tempfile, pathlib; "
             "sm = compose_summary(s, r.recorder, r.ring, wall_time_s=1.0, error=None)")

#: the launcher's figure step: from memory where the tree can (run_data), else as it did before (write the run
#: directory's data, read it back with load_run)
_FIGURES = """d = pathlib.Path(tempfile.mkdtemp())
try:
    from cosim.runtime.outputs import run_data
    rd = run_data(d, s, sm, r.recorder)
except ImportError:
    from cosim.runtime.outputs import write_outputs, write_scenario
    write_scenario(d, s)
    write_outputs(d, s, r.recorder, r.ring, wall_time_s=1.0, error=None)
    rd = cosim.report.load_run(d)
cosim.report.write_run_figures(rd)
"""

#: (name, snippet, name of the step it adds to, or None)
STEPS: tuple[tuple[str, str, str | None], ...] = (
    ("interpreter", "pass", None),
    ("launcher: command line", "import cosim.cli", "interpreter"),
    ("launcher: + scenario loaded", "import cosim.cli; " + _LOAD, "launcher: command line"),
    ("launcher: + launcher modules", "import cosim.cli; " + _LOAD + "; import cosim.runtime.launcher",
     "launcher: + scenario loaded"),
    ("launcher: + resolved scenario and schema",
     "import cosim.cli; " + _LOAD + "; import cosim.runtime.launcher; from cosim.scenario.loader import dump_resolved; "
     "dump_resolved(s); from cosim.runtime.specs import build_schema, ring_specs; build_schema(s, ring_specs(s))",
     "launcher: + launcher modules"),
    ("child: before child_main", _CHILD, "interpreter"),
    ("child: + dynamics create", _CHILD + "; from dynamics_proc.participant import create; create(s)",
     "child: before child_main"),
    ("child: + renderer create", _CHILD + "; from renderer_proc.participant import create; create(s)",
     "child: before child_main"),
    ("child: + perception create", _CHILD + "; from perception_proc.participant import create; create(s)",
     "child: before child_main"),
    ("end: run data (300 frames)", _FIG_DATA, None),
    ("end: + plotting modules", _FIG_DATA + "; import cosim.report", "end: run data (300 frames)"),
    ("end: + four figures", _FIG_DATA + "; import cosim.report\n" + _FIGURES, "end: + plotting modules"),
)


def _scenario_json(src: Path, path: Path) -> None:
    code = (_LOAD + f"; open('{path}', 'w').write(s.model_dump_json())")
    subprocess.run([sys.executable, "-c", code], cwd=src, check=True)


def instructions(src: Path, code: str) -> int:
    """Instructions of ``python -c code`` run in ``src`` under callgrind."""
    env = dict(os.environ, PYTHONHASHSEED="0")
    subprocess.run([sys.executable, "-c", code], cwd=src, env=env, check=True, stdout=subprocess.DEVNULL)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "callgrind.out"
        subprocess.run(["valgrind", "--tool=callgrind", f"--callgrind-out-file={out}", sys.executable, "-c", code],
                       cwd=src, env=env, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        return int(re.search(r"^(?:summary|totals): (\d+)", out.read_text(), re.M).group(1))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--src", type=Path, default=Path(__file__).resolve().parents[1])
    p.add_argument("--only", nargs="*", help="names (prefixes) of the steps to run")
    args = p.parse_args(argv)
    src = args.src.resolve()
    json_path = Path(tempfile.mkdtemp()) / "scenario.json"
    _scenario_json(src, json_path)
    print("| step | instructions (M) | increment (M) |")
    print("|---|---:|---:|")
    done: dict[str, int] = {}
    for name, code, adds_to in STEPS:
        if args.only and not any(name.startswith(o) for o in args.only):
            continue
        n = done[name] = instructions(src, code.replace("{json}", str(json_path)))
        inc = f"{(n - done[adds_to]) / 1e6:,.0f}" if adds_to in done else ""
        print(f"| {name} | {n / 1e6:,.0f} | {inc} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
