"""Instructions per frame of the serial ring work outside the renderer and perception (callgrind, deterministic).

Three fixed workloads of the default scenario, each a loop over frames:

* ``dynamics``: the dynamics participant's ``step`` over an in-process segment (ground-truth feedback, so the
  controller and the fused estimator get a measurement every frame without a renderer): frame step, signals,
  publishing the three blocks, the truth measurement;
* ``supervisor``: the supervisor's per-frame work on the default scenario's whole schema (GL rig, perception
  blocks): ``Recorder.record`` (every struct row and every small array block copied) and the progress callback,
  after the blocks have been stamped by their writers as in a run;
* ``stamps``: those writers' stamps alone (``Segment.write`` of every non-image block), which the supervisor
  workload also executes: subtract it for the supervisor's own work.

``python bench/frame_instructions.py WORKLOAD`` runs a workload natively and prints its median wall time per
frame. ``--callgrind`` runs it under ``valgrind --tool=callgrind`` collecting only inside frames F1..F2 (the loop
runs inside ``functools.reduce``, the collection toggle: start-up, imports and the first F1 frames are not
counted) and prints the instructions per frame. PYTHONHASHSEED is fixed and the counts repeat between runs;
compare them, not the wall times, between versions of the code. (A large memcpy counts about one instruction per
byte under callgrind.)
"""
from __future__ import annotations

import argparse
import functools
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

#: frames F1..F2 measured per workload (after F1 frames of warm-up)
SPANS = {"dynamics": (150, 450), "supervisor": (150, 1050), "stamps": (150, 1050)}
WORKLOADS = tuple(SPANS)
#: the C function that callgrind toggles collection on: the frame loop runs inside it
TOGGLE = "functools_reduce"


def _scenario(feedback: str, renderer: str):
    from cosim.scenario.loader import load_scenario, resolve_scenario_arg

    return load_scenario(resolve_scenario_arg("default"), extra={"feedback": feedback, "renderer": renderer})


def dynamics_step(frames: int):
    """step(frame) of the dynamics participant over an in-process segment."""
    from cosim.runtime.specs import build_schema, ring_specs
    from dynamics_proc.participant import create
    from shm_schema import Segment

    s = _scenario("ground_truth", "none")
    seg = Segment.local(build_schema(s, ring_specs(s)), frames=frames)
    p = create(s)
    p.start(seg)
    return p.step


def supervisor_step(frames: int, record: bool = True):
    """step(frame): the writers' stamps of every non-image block, then (``record``) the supervisor's work."""
    from cosim.runtime.progress import ProgressPrinter
    from cosim.runtime.recorder import Recorder
    from cosim.runtime.specs import build_schema, ring_specs
    from shm_schema import Segment, StructBlock

    s = _scenario("perception", "gl")
    ring = ring_specs(s)
    seg = Segment.local(build_schema(s, ring), frames=frames)
    rec = Recorder(seg, tuple(r.name for r in ring), deferred=True)
    blocks = [b.name for b in seg.schema.blocks if isinstance(b, StructBlock) or b.kind != "image"]
    progress = ProgressPrinter(open(os.devnull, "w"), tty=False)

    def step(frame: int) -> None:
        for name in blocks:
            with seg.write(name, frame):
                pass
        if record:
            rec.record(frame, 1_000_000 if frame else None)
            progress(frame, frames, frame * 0.1, 1.0)
    return step


def make_step(workload: str, frames: int):
    if workload == "dynamics":
        return dynamics_step(frames)
    return supervisor_step(frames, record=workload == "supervisor")


def run_measured(workload: str, f1: int, f2: int) -> None:
    """Frames 0..f1-1 as warm-up, then f1..f2-1 inside functools.reduce (what callgrind collects)."""
    step = make_step(workload, f2)
    for frame in range(f1):
        step(frame)
    functools.reduce(lambda _, frame: step(frame), range(f1, f2), None)


def callgrind(workload: str, f1: int, f2: int) -> int:
    """Instructions of frames f1..f2-1 of ``workload`` under callgrind (after a native run that leaves every
    module's bytecode cached)."""
    env = dict(os.environ, PYTHONHASHSEED="0")
    args = [__file__, workload, "--measured", str(f1), str(f2)]
    subprocess.run([sys.executable, *args], check=True, env=env, stdout=subprocess.DEVNULL)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "callgrind.out"
        subprocess.run(["valgrind", "--tool=callgrind", f"--toggle-collect={TOGGLE}", f"--callgrind-out-file={out}",
                        sys.executable, *args], check=True, env=env, stdout=subprocess.DEVNULL,
                       stderr=subprocess.DEVNULL)
        return int(re.search(r"^(?:summary|totals): (\d+)", out.read_text(), re.M).group(1))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("workload", choices=WORKLOADS)
    p.add_argument("--frames", type=int, default=450, help="native run: frames to time")
    p.add_argument("--callgrind", action="store_true", help="instructions per frame over frames F1..F2")
    p.add_argument("--span", type=int, nargs=2, metavar=("F1", "F2"), help="default: SPANS of the workload")
    p.add_argument("--measured", type=int, nargs=2, metavar=("F1", "F2"), help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.measured:
        run_measured(args.workload, *args.measured)
        return 0
    if args.callgrind:
        f1, f2 = args.span or SPANS[args.workload]
        n = callgrind(args.workload, f1, f2)
        print(f"{args.workload}: {n / (f2 - f1):,.0f} instructions per frame (frames {f1}..{f2 - 1}, {n:,} in all)")
        return 0
    step = make_step(args.workload, args.frames)
    clock, times = time.perf_counter_ns, []
    for frame in range(args.frames + 1):
        t0 = clock()
        step(frame)
        times.append(clock() - t0)
    times.sort()
    print(f"{args.workload}: median {times[len(times) // 2] / 1e6:.3f} ms per frame over {len(times)} frames")
    return 0


if __name__ == "__main__":
    sys.exit(main())
