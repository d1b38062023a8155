"""Instruction counts under callgrind (``harness.callgrind``): deterministic figures for A/B of source trees on a
shared machine, where timings are not.

``frame_instructions``: the serial ring work outside the renderer and perception, instructions per frame over frames
F1..F2 (after F1 frames of warm-up; the loop runs inside ``functools.reduce``, the collection toggle, so start-up
and imports are not counted):

* ``dynamics``: the dynamics participant's ``step`` over an in-process segment (ground-truth feedback, so the
  controller gets a measurement every frame without a renderer): frame step, signals, the three blocks, the truth
  measurement;
* ``supervisor``: the supervisor's per-frame work on the default scenario's whole schema (GL rig, perception blocks):
  ``Recorder.record`` and the progress callback, after the blocks have been stamped by their writers as in a run;
* ``stamps``: those writers' stamps alone, which ``supervisor`` also executes: subtract it for the supervisor's own.

``meter=wall`` times the same loops natively instead (median ms per frame).

``startup_instructions``: start-up and shut-down step by step, each a ``python -c`` snippet run in the arm's tree
after a native run that leaves every module's bytecode cached; a step that adds to another is shown with the
increment: the bare interpreter; the launcher (command line, scenario, its modules, the resolved scenario and the
schema); a spawned child before ``child_main``, then each participant's module and ``create`` (ring members forked
from the fork server pay only that part); the end of a run (the plotting modules, the four figures of a 300-frame
ground-truth run from memory).
"""
from __future__ import annotations

import functools
import os
import sys
import tempfile
import time
from pathlib import Path

from harness import Context, case

__all__ = ["frame_instructions", "make_step", "run_measured", "startup_instructions"]

#: frames F1..F2 measured per workload (after F1 frames of warm-up)
SPANS = {"dynamics": (150, 450), "supervisor": (150, 1050), "stamps": (150, 1050)}
#: the C function that callgrind toggles collection on: the frame loop runs inside it
TOGGLE = "functools_reduce"
BENCH = Path(__file__).resolve().parents[1]


def _scenario(feedback: str, renderer: str):
    from cosim.scenario.loader import load_scenario, resolve_scenario_arg

    return load_scenario(resolve_scenario_arg("default"), extra={"feedback": feedback, "renderer": renderer})


def make_step(workload: str, frames: int):
    """``step(frame)`` of ``workload`` (module docstring) over an in-process segment of ``frames`` frames."""
    from cosim.runtime.specs import build_schema, ring_specs
    from shm_schema import Segment, StructBlock

    if workload == "dynamics":
        from dynamics_proc.participant import create

        s = _scenario("ground_truth", "none")
        seg = Segment.local(build_schema(s, ring_specs(s)), frames=frames)
        p = create(s)
        p.start(seg)
        return p.step
    from cosim.runtime.progress import ProgressPrinter
    from cosim.runtime.recorder import Recorder

    s = _scenario("perception", "gl")
    ring = ring_specs(s)
    seg = Segment.local(build_schema(s, ring), frames=frames)
    rec = Recorder(seg, tuple(r.name for r in ring), deferred=True)
    blocks = [b.name for b in seg.schema.blocks if isinstance(b, StructBlock) or b.kind != "image"]
    progress = ProgressPrinter(open(os.devnull, "w"), tty=False)
    record = workload == "supervisor"

    def step(frame: int) -> None:
        for name in blocks:
            with seg.write(name, frame):
                pass
        if record:
            rec.record(frame, 1_000_000 if frame else None)
            progress(frame, frames, frame * 0.1, 1.0)
    return step


def run_measured(workload: str, f1: int, f2: int) -> None:
    """Frames 0..f1-1 as warm-up, then f1..f2-1 inside functools.reduce (what callgrind collects)."""
    step = make_step(workload, f2)
    for frame in range(f1):
        step(frame)
    functools.reduce(lambda _, frame: step(frame), range(f1, f2), None)


@case("frame_instructions", "instructions per frame of the serial ring work outside renderer and perception "
      "(callgrind): dynamics step, supervisor, stamps", options={"workloads": "dynamics,supervisor,stamps",
                                                                 "meter": "callgrind", "frames": None},
      quick={"workloads": "dynamics,stamps", "frames": 10})
def frame_instructions(ctx: Context) -> dict:
    """Each workload of ``workloads`` (module docstring); ``frames``: measured frames instead of the spans."""
    from harness.callgrind import instructions

    rows = {}
    for w in ctx["workloads"].split(","):
        f1, f2 = SPANS[w]
        if ctx["frames"]:
            f1, f2 = min(f1, ctx["frames"]), min(f1, ctx["frames"]) + ctx["frames"]
        if ctx["meter"] == "wall":
            step, times = make_step(w, f2), []
            for frame in range(f2):
                t0 = time.perf_counter_ns()
                step(frame)
                if frame >= f1:
                    times.append(time.perf_counter_ns() - t0)
            times.sort()
            rows[w] = {"frames": f2 - f1, "median ms per frame": times[len(times) // 2] / 1e6}
            continue
        code = (f"import sys; sys.path.insert(0, {str(BENCH)!r}); from cases.instructions import run_measured; "
                f"run_measured({w!r}, {f1}, {f2})")
        n = instructions(["-c", code], ctx.tree, dict(os.environ, PYTHONPATH=str(ctx.tree)), toggle=TOGGLE)
        rows[w] = {"frames": f2 - f1, "instructions per frame": n / (f2 - f1), "instructions M": n / 1e6}
    return {"serial ring work per frame": rows}


_LOAD = ("from cosim.scenario.loader import load_scenario, resolve_scenario_arg; "
         "s = load_scenario(resolve_scenario_arg('default'))")
#: a spawned child runs the launcher's main file as __mp_main__, unpickles its arguments and validates the scenario's
#: JSON ({json}: a file holding the default scenario's)
_CHILD = ("import runpy; runpy.run_path('launch.py', run_name='__mp_main__'); import multiprocessing.spawn, "
          "cosim.runtime.child; from cosim.scenario.config import Scenario; "
          "s = Scenario.model_validate_json(open('{json}').read())")
_GT = ("from cosim.scenario.loader import load_scenario, resolve_scenario_arg; "
       "s = load_scenario(resolve_scenario_arg('default'), extra={'feedback': 'ground_truth', 'renderer': 'none'})")
_FIG_DATA = (_GT + "; from cosim.runtime.inprocess import simulate; r = simulate(s, frames=300); "
             "from cosim.runtime.outputs import compose_summary; import tempfile, pathlib; "
             "sm = compose_summary(s, r.recorder, r.ring, wall_time_s=1.0, error=None)")
_FIGURES = """d = pathlib.Path(tempfile.mkdtemp())
from cosim.runtime.outputs import run_data
rd = run_data(d, s, sm, r.recorder)
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


@case("startup_instructions", "instructions of start-up and shut-down step by step (callgrind): launcher, each "
      "child's imports and create, figures", options={"only": ""}, quick={"only": "interpreter,launcher: command line"})
def startup_instructions(ctx: Context) -> dict:
    """Every step of :data:`STEPS` (``only``: comma-separated name prefixes; module docstring)."""
    import subprocess

    from harness.callgrind import instructions

    env = dict(os.environ, PYTHONPATH=str(ctx.tree))
    only = [o for o in ctx["only"].split(",") if o]
    rows, done = {}, {}
    with tempfile.TemporaryDirectory(prefix="bench-startup-cg-") as tmp:
        json_path = Path(tmp) / "scenario.json"
        subprocess.run([sys.executable, "-c", _LOAD + f"; open({str(json_path)!r}, 'w').write(s.model_dump_json())"],
                       cwd=ctx.tree, env=env, check=True)
        for name, code, adds_to in STEPS:
            if only and not any(name.startswith(o) for o in only):
                continue
            n = done[name] = instructions(["-c", code.replace("{json}", str(json_path))], ctx.tree, env)
            rows[name] = {"instructions M": n / 1e6,
                          "increment M": (n - done[adds_to]) / 1e6 if adds_to in done else None}
    return {"start-up and shut-down": rows}
