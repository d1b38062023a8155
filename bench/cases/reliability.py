"""Reliability: how fast a stopped or faulted child is named, and what kill -9 of the launcher loses.

* ``detect``: stand-ins of ``cosim.testing.fakes`` stop (SIGSTOP before frame 0 and mid-run) or deadlock (a C sleep
  holding the GIL) themselves and stamp CLOCK_MONOTONIC; the figure is the time from that stamp to the launcher's
  return (named, every child ended, outputs written).
* ``return``: the same for the real participants of the packaged default (mock renderer, perception feedback;
  ``cosim.testing.fakes.real_specs``) for each child and each kind of fault (raise, SIGSTOP, a GIL deadlock, a lock
  never released, and a runaway loop past 1.5 s of CPU time on one frame, timed from the end of that budget) at
  frame 4.
* ``kill9``: a ground-truth run (renderer none) is SIGKILLed 2.5-4.5 s into its frames; frames lost = the
  supervisor's last frame (read from the segment just before the kill) + 1 - rows in timeseries.csv.

What streaming the outputs costs the ground-truth ring is an A/B of trees:
``python bench/run.py e2e --tree base=PATH --tree this=. --set feedback=ground_truth --set renderer=none``.
"""
from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

from harness import Context, case

__all__ = ["detect", "fault_return", "kill9", "reliability"]

#: a stand-in run with one faulty participant, in a fresh interpreter (the fault may kill or stop it)
DETECT = textwrap.dedent("""
    import sys, time
    from cosim.testing import fakes
    from cosim.scenario.config import Scenario
    from cosim.runtime.launcher import launch
    if __name__ == "__main__":
        role, fault, at, out = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4]
        sc = Scenario(format_version=1, duration_s=3.0, renderer="mock")
        res = launch(sc, out, specs=fakes.specs(**{role: {fault: at, "stamp_file": out + ".stamp"}}), console_log=False)
        took = time.monotonic() - float(open(out + ".stamp").read())
        print(repr(took), type(res.error).__name__)
""")
#: (role, fault keyword, frame, label) of ``detect``
DETECT_CASES = (("renderer", "stop_at", -2, "SIGSTOP before frame 0"), ("perception", "stop_at", 5, "SIGSTOP mid-run"),
                ("dynamics", "deadlock_at", 5, "deadlock holding the GIL"))
#: fault kinds of ``return``: label -> fakes keyword
FAULTS = {"crash": "crash_at", "stop": "stop_at", "deadlock": "deadlock_at", "hang": "hang_at", "runaway": "spin_at"}


def detect(tree: Path) -> dict:
    """Seconds from each stand-in's fault to the launcher's return."""
    rows = {}
    with tempfile.TemporaryDirectory(prefix="bench-detect-") as tmp:
        script = Path(tmp) / "detect.py"
        script.write_text(DETECT)
        env = dict(os.environ, PYTHONPATH=str(tree))
        for role, fault, at, label in DETECT_CASES:
            out = str(Path(tmp) / f"run-{role}")
            line = subprocess.run([sys.executable, str(script), role, fault, str(at), out], capture_output=True,
                                  text=True, check=True, cwd=tree, env=env).stdout.split()
            if line[1] != "ParticipantHung":
                raise RuntimeError(f"{label}: the launcher reported {line[1]}, not ParticipantHung")
            rows[label] = {"launcher back after s": float(line[0])}
    return rows


def fault_return(ctx: Context) -> dict:
    """Seconds from each real child's fault to the launcher's return, per child and kind."""
    from cosim.runtime.launcher import launch
    from cosim.testing import fakes

    handoff_s, frame = 1.5, 4
    sc = ctx.scenario("default", extra={"renderer": "mock", "duration_s": 1.5, "timing": {"handoff_timeout_s": handoff_s}})
    rows = {}
    with tempfile.TemporaryDirectory(prefix="bench-return-") as tmp:
        for role in ("dynamics", "renderer", "perception"):
            for kind, keyword in FAULTS.items():
                out = Path(tmp) / f"{role}-{kind}"
                stamp = out.with_suffix(".stamp")
                res = launch(sc, out, specs=fakes.real_specs(sc, **{role: {keyword: frame, "stamp_file": str(stamp)}}),
                             console_log=False)
                took = time.monotonic() - float(stamp.read_text()) - (handoff_s if kind == "runaway" else 0)
                if res.error is None or res.error.process != role:
                    raise RuntimeError(f"{role} {kind}: the launcher named {res.error!r}")
                rows.setdefault(role, {})[f"{kind} s"] = took
    return rows


def _supervisor_frame(pid: int) -> int:
    from shm_schema import Segment

    names = [p.name for p in Path("/dev/shm").glob(f"cosim-{pid}-*")]
    if not names:
        return -1
    seg = Segment.attach(names[0])
    try:
        return int(seg.slot("supervisor")["frame"])
    finally:
        seg.close()


def kill9(tree: Path) -> dict:
    """Frames lost when a ground-truth run's launcher is SIGKILLed mid-run."""
    with tempfile.TemporaryDirectory(prefix="bench-kill9-") as tmp:
        out = Path(tmp) / "run"
        p = subprocess.Popen([sys.executable, "launch.py", "run", "default", "--renderer", "none", "--feedback",
                              "ground_truth", "--duration", "3600", "--quiet", "--out", str(out)], cwd=tree,
                             env=dict(os.environ, PYTHONPATH=str(tree)), stdout=subprocess.DEVNULL,
                             stderr=subprocess.DEVNULL)
        while _supervisor_frame(p.pid) < 0:
            if p.poll() is not None:
                raise RuntimeError(f"the run ended ({p.returncode}) before its first frame")
            time.sleep(0.05)
        time.sleep(2.5 + 2.0 * random.random())
        frame = _supervisor_frame(p.pid)
        p.send_signal(signal.SIGKILL)
        p.wait()
        rows = (out / "timeseries.csv").read_text().count("\n") - 1
        status = json.loads((out / "summary.json").read_text())["status"]
    return {"killed at frame": frame, "rows on disk": rows, "frames lost": frame + 1 - rows, "summary status": status}


@case("reliability", "how fast a stopped, hung or crashed child is named; what kill -9 of the launcher loses",
      options={"parts": "detect,kill9"}, quick={"parts": "detect"}, rounds=5)
def reliability(ctx: Context) -> dict:
    """Each part of ``parts`` (comma-separated, of detect, return, kill9; module docstring)."""
    out = {}
    for part in ctx["parts"].split(","):
        if part == "detect":
            out["stand-in faults: launcher back after (s)"] = detect(ctx.tree)
        elif part == "return":
            out["real children's faults at frame 4: launcher back after (s)"] = fault_return(ctx)
        elif part == "kill9":
            out["kill -9 of the launcher"] = {"ground-truth run": kill9(ctx.tree)}
        else:
            raise ValueError(f"unknown part {part!r}: detect, return or kill9")
    return out
