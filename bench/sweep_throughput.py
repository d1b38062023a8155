"""Sweep throughput and the engine's overhead per run (issue 17).

Run from the repository root::

    nice -n 5 python bench/sweep_throughput.py --runs 6 --rounds 3 --duration 60

Each round, in alternating order (A B C, C B A, ...), times the same N runs of the packaged default scenario,
ground truth, renderer none, ``--duration`` simulated seconds, seeds 0..N-1:

* A: ``run_sweep`` (cosim/studies/sweep.py) with 1 local worker: embedded LocalCluster, results table, no figures;
* B: N plain ``launch()`` calls one after another in this process (what a hand-written loop does);
* C: ``run_sweep`` with 2 local workers.

Reported (medians over the rounds, min-max): wall per run, runs per hour, and A's overhead against B per run,
both with the cluster's start-up and shut-down amortised over the N runs and without them (the start-up is
timed apart by opening and closing the same cluster). The figures (``write_sweep_figures``) are timed once: they
are a per-sweep cost, like the cluster.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cosim.runtime.launcher import launch  # noqa: E402
from cosim.scenario.loader import load_scenario, resolve_scenario_arg  # noqa: E402
from cosim.studies.figures import write_sweep_figures  # noqa: E402
from cosim.studies.sweep import open_client, run_sweep  # noqa: E402
from cosim.studies.sweepfile import RunSpec, Sweep, run_id  # noqa: E402


def make_sweep(n: int, duration: float) -> Sweep:
    runs = []
    for seed in range(n):
        sc = load_scenario(resolve_scenario_arg("default"), extra={"renderer": "none", "feedback": "ground_truth",
                                                                  "duration_s": duration, "seed": seed})
        runs.append(RunSpec(run_id("default", {"duration_s": duration}, {}, seed), {}, seed, sc))
    return Sweep("bench", (), tuple(runs))


def time_sweep(sweep: Sweep, jobs: int) -> float:
    with tempfile.TemporaryDirectory(prefix="sweepbench-") as tmp:
        t = time.perf_counter()
        out = run_sweep(sweep, Path(tmp), jobs=jobs, quiet=True, figures=False)
        wall = time.perf_counter() - t
    assert out.completed == len(sweep.runs), out
    return wall


def time_plain(sweep: Sweep) -> float:
    with tempfile.TemporaryDirectory(prefix="sweepbench-") as tmp:
        t = time.perf_counter()
        for run in sweep.runs:
            assert launch(run.scenario, Path(tmp) / run.id, console_log=False).completed
        return time.perf_counter() - t


def time_cluster(jobs: int) -> float:
    t = time.perf_counter()
    with open_client(None, jobs, False):
        pass
    return time.perf_counter() - t


def med(xs: list[float]) -> str:
    return f"{statistics.median(xs):.2f} ({min(xs):.2f}-{max(xs):.2f})"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=6)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--duration", type=float, default=60.0)
    args = ap.parse_args()
    sweep = make_sweep(args.runs, args.duration)
    n = args.runs
    res = {"A": [], "B": [], "C": [], "start1": []}
    steps = {"A": lambda: time_sweep(sweep, 1), "B": lambda: time_plain(sweep), "C": lambda: time_sweep(sweep, 2)}
    for r in range(args.rounds):
        for key in ("ABC" if r % 2 == 0 else "CBA"):
            res[key].append(steps[key]())
            print(f"round {r + 1} {key}: {res[key][-1]:.2f} s", file=sys.stderr)
        res["start1"].append(time_cluster(1))
    with tempfile.TemporaryDirectory() as tmp:
        rows = [{"seed": s, "completed": True, "wall_time_s": 1.0 + s} for s in range(n)]
        t = time.perf_counter()
        write_sweep_figures(Path(tmp), rows, ())
        figures = time.perf_counter() - t
    per = {k: [w / n for w in v] for k, v in res.items() if k in "ABC"}
    marginal = [(a - s) / n for a, s in zip(res["A"], res["start1"])]
    plain = statistics.median(per["B"])
    print(f"\n{n} runs x {args.duration:g} s simulated, {args.rounds} rounds; medians (min-max)\n")
    print("| | wall per run (s) | runs per hour |")
    print("|---|---:|---:|")
    for key, label in (("B", "plain launch() loop"), ("A", "sweep, 1 local worker"), ("C", "sweep, 2 local workers")):
        print(f"| {label} | {med(per[key])} | {3600 / statistics.median(per[key]):.0f} |")
    a_ratio = [a / b for a, b in zip(per["A"], per["B"])]
    m_ratio = [m / b for m, b in zip(marginal, per["B"])]
    print(f"\nengine overhead per run, 1 worker against the plain loop (same round): "
          f"{(statistics.median(a_ratio) - 1) * 100:+.1f} % with the cluster's start-up amortised over {n} runs, "
          f"{(statistics.median(m_ratio) - 1) * 100:+.1f} % without it; cluster start-up + shut-down "
          f"{med(res['start1'])} s; figures {figures:.2f} s per sweep; 2 workers / 1 worker throughput "
          f"{statistics.median([a / c for a, c in zip(res['A'], res['C'])]):.2f}x; plain run {plain:.2f} s")


if __name__ == "__main__":
    main()
