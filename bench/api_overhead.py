"""Per-frame cost of driving a run through ``cosim.Simulation`` against ``simulate()``.

The same scenario (default, ground-truth feedback, no renderer: the cheapest frame, so the API's own cost shows
most) runs whole, in this process, as ``simulate(s)``, as ``Simulation(s)`` stepped one frame per ``step()``
(each step takes a state snapshot) and stepped ten frames per call, interleaved (A/B/C, A/B/C, ...). Each
figure is the median over the rounds of wall time (set-up included) / frames. Prints a Markdown table.

Usage: ``python bench/api_overhead.py [--rounds 7] [--duration 60] [--feedback ground_truth --renderer none]``
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from cosim import Simulation  # noqa: E402
from cosim.runtime.inprocess import simulate  # noqa: E402
from cosim.scenario.options import load_with_options  # noqa: E402


def _simulate(s) -> float:
    t0 = time.perf_counter()
    simulate(s)
    return time.perf_counter() - t0


def _api(s, n: int) -> float:
    t0 = time.perf_counter()
    with Simulation(s) as sim:
        sim.reset()
        while not sim.done:
            sim.step(n)
    return time.perf_counter() - t0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--rounds", type=int, default=7)
    p.add_argument("--duration", type=float, default=60.0)
    p.add_argument("--feedback", default="ground_truth")
    p.add_argument("--renderer", default="none")
    args = p.parse_args(argv)
    s = load_with_options("default", feedback=args.feedback, renderer=args.renderer, duration=args.duration)
    frames = s.frames + 1
    cases = {"simulate()": lambda: _simulate(s), "Simulation.step(1)": lambda: _api(s, 1),
             "Simulation.step(10)": lambda: _api(s, 10)}
    for fn in cases.values():        # warm-up: imports, caches
        fn()
    times: dict[str, list[float]] = {k: [] for k in cases}
    for _ in range(args.rounds):
        for k, fn in cases.items():
            times[k].append(fn() / frames * 1e3)
    base = statistics.median(times["simulate()"])
    print(f"| {frames} frames, {args.feedback}, renderer {args.renderer} | ms/frame (median of {args.rounds}) | "
          "min | vs simulate() |")
    print("|---|---|---|---|")
    for k, v in times.items():
        med = statistics.median(v)
        print(f"| {k} | {med:.3f} | {min(v):.3f} | {med - base:+.3f} ms ({(med / base - 1) * 100:+.1f} %) |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
