"""Reliability figures: how fast a stopped child is named, what kill -9 of the launcher loses, what
streaming the outputs costs the ground-truth ring.

    python bench/reliability.py detect [--reps 7]      # SIGSTOP before frame 0 / mid-run, a GIL deadlock
    python bench/reliability.py return [--reps 3]      # real children: fault -> launcher back, per child per kind
    python bench/reliability.py kill9 [--reps 5]       # frames lost when the launcher is SIGKILLed
    python bench/reliability.py stream --main /work/main [--reps 5]   # A/B wall time, ground-truth 120 s run

``detect``: stand-ins of cosim/testing/fakes.py stop (SIGSTOP) or deadlock (a C sleep holding the GIL) themselves and
stamp CLOCK_MONOTONIC; the figure is the time from that stamp to the launcher's return (named, every child
ended, outputs written). ``return``: the same for the real participants of the packaged default (mock renderer,
perception feedback; ``cosim.testing.fakes.real_specs``) for each child and each kind of fault (raise, SIGSTOP,
a GIL deadlock, a hang past a 1.5 s hand-off timeout, timed from the timeout's end) at frame 4. ``kill9``: a ground-truth run (renderer none) is SIGKILLed 2.5-4.5 s into its frames;
frames lost = the supervisor's last frame (read from the segment just before the kill) + 1 - rows in
timeseries.csv. ``stream``: the packaged default with ground-truth feedback and no figures, run by this checkout
and by another (``--main``), interleaved A/B; the figure is summary.json's wall_time_s.
"""
from __future__ import annotations

import argparse
import json
import os
import random
import signal
import statistics
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent

DETECT = textwrap.dedent("""
    import sys, time
    sys.path[:0] = [{repo!r}, {tests!r}]
    from cosim.testing import fakes
    from cosim.scenario.config import Scenario
    from cosim.runtime.launcher import launch
    if __name__ == "__main__":
        role, fault, at, out = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4]
        sc = Scenario(format_version=1, duration_s=3.0, renderer="mock")
        res = launch(sc, out, specs=fakes.specs(**{{role: {{fault: at, "stamp_file": out + ".stamp"}}}}),
                     console_log=False)
        took = time.monotonic() - float(open(out + ".stamp").read())
        print(repr(took), type(res.error).__name__)
""")


def detect(reps: int) -> None:
    cases = [("renderer", "stop_at", -2, "SIGSTOP before frame 0"), ("perception", "stop_at", 5, "SIGSTOP mid-run"),
             ("dynamics", "deadlock_at", 5, "deadlock holding the GIL")]
    with tempfile.TemporaryDirectory() as tmp:
        script = Path(tmp) / "detect.py"
        script.write_text(DETECT.format(repo=str(REPO), tests=str(REPO / "tests")))
        times: dict[str, list[float]] = {c[3]: [] for c in cases}
        for i in range(reps):
            for role, fault, at, label in cases:
                out = str(Path(tmp) / f"run-{i}-{role}")
                line = subprocess.run([sys.executable, str(script), role, fault, str(at), out], capture_output=True,
                                      text=True, check=True).stdout.split()
                assert line[1] == "ParticipantHung", line
                times[label].append(float(line[0]))
    for label, t in times.items():
        print(f"{label}: median {statistics.median(t):.2f} s, max {max(t):.2f} s over {len(t)} runs")


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


def kill9(reps: int) -> None:
    lost = []
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(reps):
            out = Path(tmp) / f"run-{i}"
            p = subprocess.Popen([sys.executable, str(REPO / "launch.py"), "run", "default", "--renderer", "none",
                                  "--feedback", "ground_truth", "--duration", "3600", "--quiet", "--out", str(out)],
                                 cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            while _supervisor_frame(p.pid) < 0:
                time.sleep(0.05)
            time.sleep(2.5 + 2.0 * random.random())
            frame = _supervisor_frame(p.pid)
            p.send_signal(signal.SIGKILL)
            p.wait()
            rows = (out / "timeseries.csv").read_text().count("\n") - 1
            summary = json.loads((out / "summary.json").read_text())
            lost.append(frame + 1 - rows)
            print(f"killed at frame {frame}: {rows} rows on disk, summary status {summary['status']!r}")
    print(f"frames lost: median {statistics.median(lost)}, max {max(lost)} over {reps} kills")


def _gt_run(repo: Path, out: Path) -> float:
    subprocess.run([sys.executable, "launch.py", "run", "default", "--feedback", "ground_truth", "--renderer", "none",
                    "--set", "outputs.figures=false", "--quiet", "--out", str(out)], cwd=repo, check=True,
                   stdout=subprocess.DEVNULL)
    return json.loads((out / "summary.json").read_text())["wall_time_s"]


def fault_return(reps: int) -> None:
    from cosim.runtime.launcher import launch
    from cosim.scenario.loader import load_scenario, resolve_scenario_arg
    from cosim.testing import fakes

    handoff_s, frame = 1.5, 4
    kinds = {"crash": "crash_at", "stop": "stop_at", "deadlock": "deadlock_at", "hang": "hang_at"}
    sc = load_scenario(resolve_scenario_arg("default"), [], extra={"renderer": "mock", "duration_s": 1.5})
    sc = sc.model_copy(update={"timing": sc.timing.model_copy(update={"handoff_timeout_s": handoff_s})})
    with tempfile.TemporaryDirectory() as tmp:
        for role in ("dynamics", "renderer", "perception"):
            for kind, keyword in kinds.items():
                took = []
                for i in range(reps):
                    out = Path(tmp) / f"{role}-{kind}-{i}"
                    stamp = out.with_suffix(".stamp")
                    res = launch(sc, out, specs=fakes.real_specs(sc, **{role: {keyword: frame,
                                                                               "stamp_file": str(stamp)}}),
                                 console_log=False)
                    took.append(time.monotonic() - float(stamp.read_text()) - (handoff_s if kind == "hang" else 0))
                    assert res.error is not None and res.error.process == role, res.error
                print(f"{role:10s} {kind:8s} back after median {statistics.median(took):.2f} s, "
                      f"max {max(took):.2f} s ({reps} runs)", flush=True)


def stream(main: Path, reps: int) -> None:
    a, b = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(reps):
            a.append(_gt_run(main, Path(tmp) / f"main-{i}"))
            b.append(_gt_run(REPO, Path(tmp) / f"this-{i}"))
            print(f"pair {i}: main {a[-1]:.3f} s, this {b[-1]:.3f} s")
    ratio = statistics.median(y / x for x, y in zip(a, b))
    print(f"wall time median: main {statistics.median(a):.3f} s, this {statistics.median(b):.3f} s, "
          f"median pair ratio {ratio:.3f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("what", choices=("detect", "return", "kill9", "stream"))
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--main", type=Path, default=Path("/work/main"), help="checkout to compare with (stream)")
    args = ap.parse_args()
    os.chdir(REPO)
    sys.path.insert(0, str(REPO))
    {"detect": lambda: detect(args.reps), "return": lambda: fault_return(args.reps), "kill9": lambda: kill9(args.reps),
     "stream": lambda: stream(args.main, args.reps)}[args.what]()


if __name__ == "__main__":
    main()
