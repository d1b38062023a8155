"""Sweep throughput and the engine's overhead per run.

Run from the repository root::

    nice -n 5 python bench/sweep_throughput.py --runs 6 --rounds 3 --duration 60

Each round, in alternating order (A B C, C B A, ...), times the same N runs of the packaged default scenario,
ground truth, renderer none, ``--duration`` simulated seconds, seeds 0..N-1:

* A: ``run_sweep`` (cosim/studies/sweep.py) with 1 local worker: embedded LocalCluster, results table, no figures;
* B: N plain ``launch()`` calls one after another in this process (what a hand-written loop does);
* C: ``run_sweep`` with 2 local workers;
* D: ``run_sweep`` with 1 local worker and only the first run: the per-sweep fixed cost (cluster start-up and
  shut-down, the worker's first imports) plus one run.

Reported (medians over the rounds, min-max): wall per run, runs per hour, and A's overhead against B per run,
with the fixed cost amortised over the N runs ("all in") and per run at the margin: (A - D) / (N - 1), in wall
time and in CPU time (this process and its reaped descendants: the workers and every run's processes), against
B / N. CPU is the steadier figure on a shared machine. Also printed: the steady-state interval between the first
and the last run's summary.json (mtimes) over N - 1, the cluster's start-up and shut-down timed apart, and the
figures (``write_sweep_figures``, a per-sweep cost) timed once.
"""
from __future__ import annotations

import argparse
import resource
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


def steady(runs_dir: Path) -> float:
    """Seconds per run between the first and the last run's summary.json."""
    t = sorted(p.stat().st_mtime_ns for p in runs_dir.glob("*/summary.json"))
    return (t[-1] - t[0]) / 1e9 / (len(t) - 1) if len(t) > 1 else float("nan")


def cpu() -> float:
    """CPU seconds of this process and of its reaped descendants (a worker's runs are reaped by the worker,
    the worker by this process once the cluster closes)."""
    me, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


def time_sweep(sweep: Sweep, jobs: int) -> tuple[float, float, float]:
    with tempfile.TemporaryDirectory(prefix="sweepbench-") as tmp:
        t, c = time.perf_counter(), cpu()
        out = run_sweep(sweep, Path(tmp), jobs=jobs, quiet=True, figures=False)
        wall = time.perf_counter() - t
        assert out.completed == len(sweep.runs), out
        return wall, steady(Path(tmp) / "runs"), cpu() - c


def time_plain(sweep: Sweep) -> tuple[float, float, float]:
    with tempfile.TemporaryDirectory(prefix="sweepbench-") as tmp:
        t, c = time.perf_counter(), cpu()
        for run in sweep.runs:
            assert launch(run.scenario, Path(tmp) / "runs" / run.id, console_log=False).completed
        return time.perf_counter() - t, steady(Path(tmp) / "runs"), cpu() - c


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
    st = {"A": [], "B": [], "C": []}
    cp = {"A": [], "B": [], "C": []}
    first = Sweep(sweep.name, sweep.parameters, sweep.runs[:1])
    res["D"], st["D"], cp["D"] = [], [], []
    steps = {"A": lambda: time_sweep(sweep, 1), "B": lambda: time_plain(sweep), "C": lambda: time_sweep(sweep, 2),
             "D": lambda: time_sweep(first, 1)}
    for r in range(args.rounds):
        for key in ("ABCD" if r % 2 == 0 else "DCBA"):
            wall, per_run, used = steps[key]()
            res[key].append(wall)
            st[key].append(per_run)
            cp[key].append(used)
            print(f"round {r + 1} {key}: {wall:.2f} s, steady {per_run:.2f} s per run, cpu {used:.2f} s",
                  file=sys.stderr)
        res["start1"].append(time_cluster(1))
    with tempfile.TemporaryDirectory() as tmp:
        rows = [{"seed": s, "completed": True, "wall_time_s": 1.0 + s} for s in range(n)]
        t = time.perf_counter()
        write_sweep_figures(Path(tmp), rows, ())
        figures = time.perf_counter() - t
    per = {k: [w / n for w in v] for k, v in res.items() if k in "ABC"}
    cpu_per = {k: [c / n for c in cp[k]] for k in "ABC"}
    margin = [(a - d) / (n - 1) for a, d in zip(res["A"], res["D"])]
    margin_cpu = [(a - d) / (n - 1) for a, d in zip(cp["A"], cp["D"])]
    plain = statistics.median(per["B"])
    print(f"\n{n} runs x {args.duration:g} s simulated, {args.rounds} rounds; medians (min-max)\n")
    print("| | wall per run, all in (s) | runs per hour, all in | steady state per run (s) | CPU per run, all in (s) |")
    print("|---|---:|---:|---:|---:|")
    for key, label in (("B", "plain launch() loop"), ("A", "sweep, 1 local worker"), ("C", "sweep, 2 local workers")):
        print(f"| {label} | {med(per[key])} | {3600 / statistics.median(per[key]):.0f} | {med(st[key])} | "
              f"{med(cpu_per[key])} |")
    print(f"| sweep, 1 local worker, per run at the margin (A - D) / (N - 1) | {med(margin)} | "
          f"{3600 / statistics.median(margin):.0f} | | {med(margin_cpu)} |")
    print(f"| fixed cost of a sweep (D minus one plain run) | {med([d - b for d, b in zip(res['D'], per['B'])])} | | | "
          f"{med([d - b for d, b in zip(cp['D'], cpu_per['B'])])} |")
    a_ratio = [a / b for a, b in zip(per["A"], per["B"])]
    m_ratio = [a / b for a, b in zip(st["A"], st["B"])]
    w_ratio = [m / b for m, b in zip(margin, per["B"])]
    c_ratio = [m / b for m, b in zip(margin_cpu, cpu_per["B"])]
    print(f"\nengine overhead per run, 1 worker against the plain loop (ratio in each round, median): "
          f"{(statistics.median(a_ratio) - 1) * 100:+.1f} % all in (the cluster's start-up amortised over {n} runs), "
          f"{(statistics.median(m_ratio) - 1) * 100:+.1f} % in steady state (mtimes); at the margin "
          f"{(statistics.median(w_ratio) - 1) * 100:+.1f} % wall, {(statistics.median(c_ratio) - 1) * 100:+.1f} % CPU; "
          f"CPU all in {(statistics.median([a / b for a, b in zip(cpu_per['A'], cpu_per['B'])]) - 1) * 100:+.1f} %; "
          f"cluster start-up + shut-down "
          f"{med(res['start1'])} s; figures {figures:.2f} s per sweep; 2 workers / 1 worker throughput "
          f"{statistics.median([a / c for a, c in zip(res['A'], res['C'])]):.2f}x; plain run {plain:.2f} s")


if __name__ == "__main__":
    main()
