"""``member_instructions``: instructions per frame of each ring member's step in a perception-in-the-loop run.

The scenario (default: ``default``, GL beam-native LiDAR) in one process (``cosim.runtime.inprocess``, the
participants and blocks of a launched run) under ``valgrind --tool=callgrind`` with collection off, llvmpipe in the
calling thread (``LP_NUM_THREADS=0``, so its vertex, geometry and fragment shading are counted with the step that
causes them); collection is switched on around each call of one member's step (and of the rest of an overlapping
member's step) over frames F1..F2 after F1 frames of warm-up, one valgrind run per member. Counts do not depend on
the machine's load: the figure for an A/B of the renderer's or the dynamics' per-frame work on a shared machine
(``frame_path`` times the same parts in thread CPU).
"""
from __future__ import annotations

import os
from pathlib import Path

from harness import Context, case

__all__ = ["member_instructions", "run_member"]

BENCH = Path(__file__).resolve().parents[1]


def run_member(scenario_arg: str, member: str, f1: int, f2: int) -> None:
    """Run the scenario in process for ``f2`` frames, callgrind collecting inside ``member``'s step from frame
    ``f1`` on (:class:`harness.callgrind.ClientRequests`; nothing outside valgrind)."""
    os.environ.setdefault("LP_NUM_THREADS", "0")                  # before GL loads: llvmpipe in this thread
    from harness.callgrind import ClientRequests

    from cosim.runtime.heap import keep_heap
    from cosim.runtime.inprocess import InProcessSession
    from cosim.scenario.loader import load_scenario, resolve_scenario_arg

    keep_heap()
    toggle = ClientRequests().lib.cg_toggle
    sess = InProcessSession(load_scenario(resolve_scenario_arg(scenario_arg)))
    p, on = sess.participants[member], [False]
    step = p.step

    def counted(fn, *args):
        toggle()
        try:
            return fn(*args)
        finally:
            toggle()

    def measured(frame):
        if not on[0]:
            return step(frame)
        rest = counted(step, frame)
        return None if rest is None else (lambda: counted(rest))
    p.step = measured
    try:
        for frame in range(f2):
            on[0] = frame >= f1
            sess.step()
    finally:
        sess.close()


@case("member_instructions", "instructions per frame (callgrind) of each ring member's step in a perception run, "
      "llvmpipe's shading included", options={"scenario": "default", "members": "renderer,dynamics",
                                              "warmup": 100, "frames": 30},
      quick={"members": "dynamics", "warmup": 2, "frames": 2})
def member_instructions(ctx: Context) -> dict:
    """Each member of ``members`` over ``frames`` frames after ``warmup`` (module docstring)."""
    from harness.callgrind import instructions

    rows = {}
    f1, f2 = ctx["warmup"], ctx["warmup"] + ctx["frames"]
    for m in ctx["members"].split(","):
        code = (f"import sys; sys.path.insert(0, {str(BENCH)!r}); from cases.members import run_member; "
                f"run_member({ctx['scenario']!r}, {m!r}, {f1}, {f2})")
        n = instructions(["-c", code], ctx.tree, dict(os.environ, PYTHONPATH=str(ctx.tree)), warm=False,
                         options=["--collect-atstart=no"])
        rows[m] = {"frames": ctx["frames"], "M instructions per frame": n / ctx["frames"] / 1e6}
    return {f"{ctx['scenario']}: instructions per frame of a member's step": rows}
