"""Instructions per frame of the serial ring work outside the renderer and perception (callgrind, deterministic).

Two fixed workloads of the default scenario, each a loop over frames:

* ``dynamics``: the dynamics participant's ``step`` over an in-process segment (ground-truth feedback, so the
  controller and the fused estimator get a measurement every frame without a renderer): frame step, signals,
  publishing the three blocks, the truth measurement;
* ``supervisor``: the supervisor's per-frame work on the default scenario's whole schema (GL rig, perception
  blocks): ``Recorder.record`` (every struct row and every small array block copied) and the progress callback,
  the blocks stamped by their writers every frame as in a run;
* ``stamps``: those writers' stamps alone (``Segment.write`` of every non-image block): subtract it from
  ``supervisor`` for the supervisor's own work.

``python bench/frame_instructions.py WORKLOAD --frames N`` runs a workload natively and prints its median wall
time per frame. ``--callgrind`` runs it twice under ``valgrind --tool=callgrind`` (F1 and F2 frames, ``SPANS``)
and prints (instructions(F2) - instructions(F1)) / (F2 - F1): the per-frame count over frames F1..F2, start-up
and imports cancelled out. PYTHONHASHSEED is fixed; start-up still varies by up to ~6 M instructions between
runs, i.e. ~20 k per frame on the dynamics span and ~7 k on the supervisor's. Compare these counts, not the wall
times, between versions of the code. (A large memcpy counts about one instruction per byte under callgrind.)
"""
from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

#: frame counts of the two callgrind runs per workload: their difference is measured (the supervisor's span is
#: longer: its per-frame count is small beside the few million instructions that start-up varies by)
SPANS = {"dynamics": (150, 450), "supervisor": (150, 1050), "stamps": (150, 1050)}
WORKLOADS = ("dynamics", "supervisor", "stamps")


def _scenario(feedback: str, renderer: str):
    from cosim.loader import load_scenario, resolve_scenario_arg

    return load_scenario(resolve_scenario_arg("default"), extra={"feedback": feedback, "renderer": renderer})


def run_dynamics(frames: int) -> list[float]:
    """Step the dynamics participant over frames 0..frames; wall ns per frame."""
    from cosim.specs import build_schema, ring_specs
    from dynamics_proc.participant import create
    from shm_schema import Segment

    s = _scenario("ground_truth", "none")
    seg = Segment.local(build_schema(s, ring_specs(s)), frames=frames)
    p = create(s)
    p.start(seg)
    clock, out = time.perf_counter_ns, []
    for frame in range(frames + 1):
        t0 = clock()
        p.step(frame)
        out.append(clock() - t0)
    p.close()
    return out


def run_supervisor(frames: int, record: bool = True) -> list[float]:
    """The supervisor's per-frame work on the default scenario's schema (only the writers' stamps without
    ``record``); wall ns per frame."""
    from cosim.progress import ProgressPrinter
    from cosim.recorder import Recorder
    from cosim.specs import build_schema, ring_specs
    from shm_schema import Segment, StructBlock

    s = _scenario("perception", "gl")
    ring = ring_specs(s)
    seg = Segment.local(build_schema(s, ring), frames=frames)
    members = tuple(r.name for r in ring)
    rec = Recorder(seg, members, deferred=True)
    blocks = [b.name for b in seg.schema.blocks if isinstance(b, StructBlock) or b.kind != "image"]
    progress = ProgressPrinter(open(os.devnull, "w"), tty=False)
    clock, out = time.perf_counter_ns, []
    for frame in range(frames + 1):
        for name in blocks:                       # the writers' stamps (not timed)
            with seg.write(name, frame):
                pass
        t0 = clock()
        if record:
            rec.record(frame, 1_000_000 if frame else None)
            progress(frame, frames, frame * 0.1, 1.0)
        out.append(clock() - t0)
    return out


def _callgrind(workload: str, frames: int) -> int:
    """Total instructions of one run of ``workload`` under callgrind (after a native run that leaves every
    module's bytecode cached, so that both runs of a difference import the same way)."""
    env = dict(os.environ, PYTHONHASHSEED="0")
    subprocess.run([sys.executable, __file__, workload, "--frames", "1"], check=True, env=env,
                   stdout=subprocess.DEVNULL)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "callgrind.out"
        subprocess.run(["valgrind", "--tool=callgrind", f"--callgrind-out-file={out}", sys.executable, __file__,
                        workload, "--frames", str(frames)], check=True, env=env, stdout=subprocess.DEVNULL,
                       stderr=subprocess.DEVNULL)
        m = re.search(r"^(?:summary|totals): (\d+)", out.read_text(), re.M)
        return int(m.group(1))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("workload", choices=WORKLOADS)
    p.add_argument("--frames", type=int, default=450)
    p.add_argument("--callgrind", action="store_true", help="instructions per frame over frames F1..F2")
    p.add_argument("--span", type=int, nargs=2, metavar=("F1", "F2"), help="default: SPANS of the workload")
    args = p.parse_args(argv)
    if args.callgrind:
        f1, f2 = args.span or SPANS[args.workload]
        i1, i2 = _callgrind(args.workload, f1), _callgrind(args.workload, f2)
        print(f"{args.workload}: {(i2 - i1) / (f2 - f1):,.0f} instructions per frame (frames {f1}..{f2}; "
              f"totals {i1:,} / {i2:,})")
        return 0
    if args.workload == "dynamics":
        times = run_dynamics(args.frames)
    else:
        times = run_supervisor(args.frames, record=args.workload == "supervisor")
    times.sort()
    print(f"{args.workload}: median {times[len(times) // 2] / 1e6:.3f} ms per frame over {len(times)} frames")
    return 0


if __name__ == "__main__":
    sys.exit(main())
