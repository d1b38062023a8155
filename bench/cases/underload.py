"""Under load: K busy processes beside the runs (``cosim.testing.load``), as on a user's laptop or a shared runner.

Three parts (option ``parts``):

* ``scenarios``: every packaged scenario for ``duration`` s simulated (``python launch.py run NAME --duration D``,
  GL), ``repeats`` times, the first with an empty Mesa shader cache (the README's first run); a **false fault** is
  a run that did not complete (a healthy run must never fail on a busy machine; target 0). Figures: completed /
  runs, and the median wall time per scenario.
* ``record``: the default scenario recorded (``--record``) for ``duration`` s: whole (the recording reads back
  with every frame) or not.
* ``hangs``: real hangs injected in the stand-in ring (``cosim.testing.fakes``) under both schedules: SIGSTOP, a
  GIL deadlock (a C sleep holding the GIL) and a lock that is never released; the figure is the time from the
  fault to the launcher's return, and whether the right member was named (target: within 6 s under load).
* ``suite`` (not in the default parts: about an hour at load 12): ``python -m pytest`` beside the busy processes;
  its wall time and result.

``results=PATH`` writes the tables as the "Under load" section of PATH (bench/results.md; ``run_all.py`` keeps it)::

    python bench/run.py underload --opt results=bench/results.md          # K=10, every scenario, 10 s, 1 repeat
    python bench/run.py underload --quick                                  # a check: 2 scenarios, 2 s
"""
from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

from harness import Context, case
from harness.report import put_results_section

__all__ = ["underload", "SECTION", "put_section"]

#: the heading of this case's section in bench/results.md
SECTION = "## Under load"
#: a stand-in run with one hung member, in a fresh interpreter (the fault may stop it)
HANG = textwrap.dedent("""
    import sys, time
    from cosim.testing import fakes
    from cosim.scenario.config import Scenario
    from cosim.runtime.launcher import launch
    if __name__ == "__main__":
        fault, schedule, out = sys.argv[1], sys.argv[2], sys.argv[3]
        make = fakes.pipelined_specs if schedule == "pipelined" else fakes.specs
        sc = Scenario(format_version=1, duration_s=3.0, renderer="mock")
        res = launch(sc, out, specs=make(dynamics={fault: 3, "stamp_file": out + ".stamp"}), console_log=False)
        took = time.monotonic() - float(open(out + ".stamp").read())
        print(repr(took), type(res.error).__name__, res.error.process if res.error else "-")
""")
#: the injected hangs: label -> fakes keyword
HANGS = {"SIGSTOP": "stop_at", "GIL deadlock": "deadlock_at", "lock never released": "hang_at"}


def _env(tree: Path, **extra: str) -> dict:
    return dict(os.environ, PYTHONPATH=str(tree), **extra)


def _scenarios(tree: Path, names: list[str], duration: float, repeats: int, tmp: Path) -> dict:
    rows: dict[str, dict] = {}
    for r in range(repeats):
        cache = tempfile.mkdtemp(prefix="mesa-cache-", dir=tmp) if r == 0 else str(tmp / "mesa-warm")
        for name in names:
            out = tmp / f"{name}-{r}"
            t0 = time.monotonic()
            p = subprocess.run([sys.executable, "launch.py", "run", name, "--duration", str(duration), "--out",
                                str(out), "--overwrite", "--quiet", "--set", "outputs.figures=false"], cwd=tree,
                               env=_env(tree, MESA_SHADER_CACHE_DIR=cache), capture_output=True, text=True)
            wall = time.monotonic() - t0
            try:
                summary = json.loads((out / "summary.json").read_text())
            except (OSError, ValueError):
                summary = {}
            row = rows.setdefault(name, {"runs": 0, "completed": 0, "walls": [], "faults": []})
            row["runs"] += 1
            row["walls"].append(wall)
            if p.returncode == 0 and summary.get("completed"):
                row["completed"] += 1
            else:
                err = summary.get("error") or {}
                row["faults"].append(f"repeat {r}: exit {p.returncode}: {err.get('message', p.stderr[-300:])}")
    return {n: {"completed / runs": f"{v['completed']} / {v['runs']}", "false faults": v["runs"] - v["completed"],
                "wall s (median)": statistics.median(v["walls"]), "first fault": (v["faults"] or ["-"])[0][:200]}
            for n, v in rows.items()}


def _record(tree: Path, duration: float, tmp: Path) -> dict:
    out = tmp / "recorded"
    p = subprocess.run([sys.executable, "launch.py", "run", "default", "--renderer", "mock", "--duration",
                        str(duration), "--record", "--out", str(out), "--overwrite", "--quiet", "--set",
                        "outputs.figures=false"], cwd=tree, env=_env(tree), capture_output=True, text=True)
    frames = int(round(duration / 0.1)) + 1
    got = -1
    if (out / "recording.mcap").exists():
        check = subprocess.run([sys.executable, "-c", "import sys; from cosim.recording.reader import read_recording; "
                                "r = read_recording(sys.argv[1]); print(-1 if r.truncated else len(r.frames))",
                                str(out / "recording.mcap")],
                               cwd=tree, env=_env(tree), capture_output=True, text=True)
        got = int(check.stdout.strip() or -1) if check.returncode == 0 else -1
    return {"default, --record": {"exit": p.returncode, "frames recorded / run": f"{got} / {frames}",
                                  "whole": got == frames}}


def _hangs(tree: Path, tmp: Path) -> dict:
    script = tmp / "hang.py"
    script.write_text(HANG)
    rows = {}
    for label, fault in HANGS.items():
        for schedule in ("sequential", "pipelined"):
            out = str(tmp / f"hang-{fault}-{schedule}")
            line = subprocess.run([sys.executable, str(script), fault, schedule, out], capture_output=True, text=True,
                                  cwd=tree, env=_env(tree)).stdout.split()
            rows[f"{label}, {schedule}"] = {"named after s": float(line[0]) if line else float("nan"),
                                            "error": line[1] if line else "none",
                                            "right member": bool(line) and line[2] == "dynamics"}
    return rows


def _suite(tree: Path) -> dict:
    t0 = time.monotonic()
    p = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider"], cwd=tree, env=_env(tree),
                       capture_output=True, text=True)
    tail = (p.stdout.strip().splitlines() or [""])[-1]
    return {"python -m pytest": {"exit": p.returncode, "wall s": time.monotonic() - t0, "result": tail[:120]}}


@case("underload", "false faults of healthy runs and the naming time of real hangs beside K busy processes",
      options={"busy": 10, "duration": 10.0, "repeats": 1, "scenarios": "all", "parts": "scenarios,record,hangs",
               "results": ""},
      quick={"busy": 4, "duration": 2.0, "scenarios": "default,dusty", "parts": "scenarios,hangs"})
def underload(ctx: Context) -> dict:
    """The parts of ``parts`` beside ``busy`` spinning processes (module docstring)."""
    sys.path.insert(0, str(ctx.tree))
    from cosim.scenario.loader import packaged_scenarios
    from cosim.testing.load import busy, load_average

    names = sorted(packaged_scenarios()) if ctx["scenarios"] == "all" else ctx["scenarios"].split(",")
    out: dict = {}
    with tempfile.TemporaryDirectory(prefix="bench-underload-") as tmp, busy(int(ctx["busy"])):
        tmp_path = Path(tmp)
        (tmp_path / "mesa-warm").mkdir()
        time.sleep(5.0)  # let the load average see the busy processes
        load0 = load_average()
        for part in ctx["parts"].split(","):
            if part == "scenarios":
                out[f"packaged scenarios, {ctx['duration']:g} s simulated"] = _scenarios(
                    ctx.tree, names, float(ctx["duration"]), int(ctx["repeats"]), tmp_path)
            elif part == "record":
                out["a recorded run"] = _record(ctx.tree, float(ctx["duration"]), tmp_path)
            elif part == "hangs":
                out["real hangs: launcher back after the fault"] = _hangs(ctx.tree, tmp_path)
            elif part == "suite":
                out["the test suite"] = _suite(ctx.tree)
            else:
                raise ValueError(f"unknown part {part!r}: scenarios, record, hangs or suite")
        out["load"] = {"machine": {"busy processes": int(ctx["busy"]), "cores": os.cpu_count(),
                                   "load average (1 min) at start": load0, "at end": load_average()}}
    if ctx["results"] and not ctx.quick:
        put_section(ctx.path(ctx["results"]), out)
    return out


def put_section(results_md: Path, tables: dict) -> None:
    """Write ``tables`` as the "Under load" section of ``results_md``, replacing the one there."""
    put_results_section(results_md, SECTION, ["Written by `python bench/run.py underload --opt "
                                              f"results=bench/results.md` ({time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}).",
                                              ""], tables)
