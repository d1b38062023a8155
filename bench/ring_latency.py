"""Ring round-trip latency: three OS processes passing the token over semaphores.

Two measurements:
* ``bare``: three spawned processes running ``cosim.runtime.lockstep.member_loop`` with trivial steps; the first member
  times each full turn (its step start to the next one). Payloads: none, or a 640 x 480 x 4 image written by
  member 2 and read (summed) by member 3.
* ``launcher``: the real launcher with stand-in participants (adds the supervisor's hop and its per-frame
  recording), turn times from the recorder.

Usage: ``python bench/ring_latency.py [--frames N]``. Prints a Markdown table.
"""
from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "tests"))

from cosim.runtime.lockstep import RingPlan, Token, member_loop  # noqa: E402
from shm_schema import ArrayBlock, Schema, Segment, image_block  # noqa: E402

FRAME_BUDGET_MS = 10.0
MEMBERS = ("m0", "m1", "m2")


class _Member:
    def __init__(self, name, seg, payload):
        self.name, self.seg, self.payload = name, seg, payload
        self.stamps = seg.view("stamps")

    def step(self, frame):
        if self.name == "m0":
            self.stamps[frame] = time.perf_counter_ns()
        elif self.payload and self.name == "m1":
            with self.seg.write("img", frame) as img:
                img[..., 0] = frame & 0xFF
        elif self.payload and self.name == "m2":
            int(self.seg.view("img")[..., 0].sum())


def _run_member(name, seg_name, sems, plan, payload):
    seg = Segment.attach(seg_name)
    member_loop(name, _Member(name, seg, payload), seg, Token(seg, sems), plan,
                startup_timeout_s=60, handoff_timeout_s=10)
    seg.close()


def bare_ring(frames: int, payload: bool) -> np.ndarray:
    """Turn times (us) of a three-process ring closed by its first member."""
    blocks = [ArrayBlock("stamps", "m0", "i8", (frames + 2,)), ArrayBlock("steps", "m0", "i8", (frames + 1,))]
    if payload:
        blocks.append(image_block("img", "m1", 480, 640))
    schema = Schema(blocks, list(MEMBERS))
    # a ring of exactly three: m2 hands back to m0 (the 'supervisor' role is played by m0 itself)
    plan = RingPlan(MEMBERS[1:], frames, supervisor="m0")
    ctx = mp.get_context("spawn")
    sems = {m: ctx.Semaphore(0) for m in MEMBERS}
    name = f"cosim-bench-{os.getpid()}"
    with Segment.create(name, schema) as seg:
        procs = [ctx.Process(target=_run_member, args=(m, name, sems, plan, payload)) for m in MEMBERS[1:]]
        for p in procs:
            p.start()
        tok = Token(seg, sems)
        stamps, steps = seg.view("stamps"), seg.view("steps")
        me = _Member("m0", seg, payload)
        slots = [seg.slot(m) for m in MEMBERS[1:]]
        for frame in range(frames + 1):
            me.step(frame)
            tok.give("m1", frame)
            tok.take("m0", frame, 60.0)
            steps[frame] = sum(int(s["step_ns"]) for s in slots)
        stamps[frames + 1] = time.perf_counter_ns()
        for p in procs:
            p.join(10)
        turns = np.diff(stamps[1:frames + 2]).astype(np.float64) / 1e3
        handoffs = turns - steps[1:frames + 1] / 1e3
    return turns, handoffs


def launcher_ring(frames: int) -> dict:
    from cosim.runtime.launcher import launch
    from cosim.scenario.config import Scenario
    from cosim.testing import fakes

    period = 0.01
    sc = Scenario(format_version=1, duration_s=frames * period, renderer="mock")
    sc = sc.model_copy(update={"timing": sc.timing.model_copy(update={"sensor_period_s": period,
                                                                      "dynamics_dt_s": period})})
    res = launch(sc, f"/tmp/cosim-bench-ring-{os.getpid()}", specs=fakes.specs(), console_log=False)
    return res.summary


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=5000)
    args = ap.parse_args()
    print("| ring | payload | frames | median turn (us) | p99 turn (us) | median hand-offs (us) | "
          "hand-off share of a 10 ms frame |")
    print("|---|---|---|---|---|---|---|")
    for payload in (False, True):
        t, h = bare_ring(args.frames, payload)
        t, h = t[100:], h[100:]  # drop warm-up
        med, p99, hmed = np.median(t), np.percentile(t, 99), np.median(h)
        print(f"| 3 processes (bare) | {'640x480x4 image' if payload else 'none'} | {len(t)} | {med:.1f} | "
              f"{p99:.1f} | {hmed:.1f} | {hmed / (FRAME_BUDGET_MS * 1e3) * 100:.2f} % |")
    s = launcher_ring(args.frames)
    ring = s["ring"]
    print(f"| launcher (3 + supervisor) | stand-ins | {s['frames']} | {ring['turn_median_ms'] * 1e3:.1f} | "
          f"{ring['turn_p99_ms'] * 1e3:.1f} | {ring['handoff_median_ms'] * 1e3:.1f} | "
          f"{ring['handoff_median_ms'] / FRAME_BUDGET_MS * 100:.2f} % |")


if __name__ == "__main__":
    main()
