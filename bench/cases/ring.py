"""The lockstep ring's round trip: three OS processes passing the token over semaphores.

* bare: three spawned processes running ``cosim.runtime.lockstep.member_loop`` with trivial steps; the first member
  times each full turn (its step start to the next one). Payloads: none, or a 640 x 480 x 4 image written by
  member 2 and read (summed) by member 3. Hand-offs: a turn less the members' steps.
* launcher: the real launcher with stand-in participants (``cosim.testing.fakes``: adds the supervisor's hop and its
  per-frame recording), turn times from the run's summary.
"""
from __future__ import annotations

import os
import time

from harness import Context, case

__all__ = ["bare_ring", "launcher_ring", "ring_latency"]

#: the frame the hand-offs are compared with, ms
FRAME_BUDGET_MS = 10.0
#: turns left out at the start (warm-up)
WARMUP_TURNS = 100
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
    from cosim.runtime.lockstep import Token, member_loop
    from shm_schema import Segment

    seg = Segment.attach(seg_name)
    member_loop(name, _Member(name, seg, payload), seg, Token(seg, sems), plan, startup_timeout_s=60,
                handoff_timeout_s=10)
    seg.close()


def bare_ring(frames: int, payload: bool):
    """(turn times, hand-off times) in us, (frames,) float64, of a three-process ring closed by its first member."""
    import multiprocessing as mp

    import numpy as np

    from cosim.runtime.lockstep import RingPlan, Token
    from shm_schema import ArrayBlock, Schema, Segment, image_block

    blocks = [ArrayBlock("stamps", "m0", "i8", (frames + 2,)), ArrayBlock("steps", "m0", "i8", (frames + 1,))]
    if payload:
        blocks.append(image_block("img", "m1", 480, 640))
    schema = Schema(blocks, list(MEMBERS))
    plan = RingPlan(MEMBERS[1:], frames, supervisor="m0")      # m2 hands back to m0, which plays the supervisor
    ctx = mp.get_context("spawn")
    sems = {m: ctx.Semaphore(0) for m in MEMBERS}
    name = f"cosim-bench-ring-{os.getpid()}"
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
    """summary.json of a launched run of ``frames`` 10 ms frames with stand-in participants."""
    import tempfile

    from cosim.runtime.launcher import launch
    from cosim.scenario.config import Scenario
    from cosim.testing import fakes

    period = 0.01
    sc = Scenario(format_version=1, duration_s=frames * period, renderer="mock")
    sc = sc.model_copy(update={"timing": sc.timing.model_copy(update={"sensor_period_s": period,
                                                                      "dynamics_dt_s": period})})
    with tempfile.TemporaryDirectory(prefix="bench-ring-") as tmp:
        return launch(sc, f"{tmp}/run", specs=fakes.specs(), console_log=False).summary


@case("ring_latency", "the lockstep ring's round trip over semaphores: bare 3-process ring and the launcher's",
      options={"frames": 5000}, quick={"frames": 300})
def ring_latency(ctx: Context) -> dict:
    """Median and p99 turn of a bare three-process ring (no payload, a 640 x 480 x 4 image) and of the launcher's
    ring with stand-in participants; the hand-offs' share of a 10 ms frame."""
    import numpy as np

    rows = {}
    for payload in (False, True):
        t, h = bare_ring(ctx["frames"], payload)
        t, h = t[WARMUP_TURNS:], h[WARMUP_TURNS:]
        rows[f"3 processes (bare), {'640x480x4 image' if payload else 'no payload'}"] = {
            "frames": len(t), "median turn us": float(np.median(t)), "p99 turn us": float(np.percentile(t, 99)),
            "median hand-offs us": float(np.median(h)),
            "hand-offs, % of a 10 ms frame": float(np.median(h)) / (FRAME_BUDGET_MS * 1e3) * 100}
    s = launcher_ring(ctx["frames"])
    ring = s["ring"]
    rows["launcher (3 + supervisor), stand-ins"] = {
        "frames": s["frames"], "median turn us": ring["turn_median_ms"] * 1e3, "p99 turn us": ring["turn_p99_ms"] * 1e3,
        "median hand-offs us": ring["handoff_median_ms"] * 1e3,
        "hand-offs, % of a 10 ms frame": ring["handoff_median_ms"] / FRAME_BUDGET_MS * 100}
    return {"": rows}
