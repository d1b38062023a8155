"""Sweeps (``launch.py sweep``, ``cosim.studies.sweep.run_sweep`` on an embedded Dask LocalCluster): throughput, and
the engine's own cost.

``sweep_throughput``: the same ``runs`` runs of the default scenario (``feedback``, ``duration`` simulated seconds,
seeds 0..N-1) in each arm, the arms' order alternating with the round: ``sweep1`` and ``sweep2`` (``run_sweep`` with 1
and 2 local workers: cluster, results table, no sweep figures), ``plain`` (N ``launch()`` calls one after another in
this process: what a hand-written loop does) and ``first`` (``sweep1`` with the first run only: the per-sweep fixed
cost, cluster start-up and shut-down and the worker's first imports, plus one run). Per arm: wall and CPU per run
all in (CPU of this process and its reaped descendants, this process the subreaper: the workers and every run's
processes), runs per hour, and the steady-state interval between the first and the last run's summary.json over
N - 1. With ``sweep1``, ``plain`` and ``first``: the engine's overhead per run at the margin, (sweep1 - first) /
(N - 1), against a plain run; the cluster's start-up and shut-down timed apart; the sweep figures timed once.

``sweep_engine``: the engine with the run taken out (a runner that returns a completed summary at once; everything
else as in a sweep: 1 local worker, submit, scheduling, result transfer, the results table rewritten after each
run), ``tasks`` runs against 1: the engine's wall and CPU per run; then the embedded cluster idle for ``idle``
seconds: the CPU its processes use per second while a run goes, less an open-close with no wait.
"""
from __future__ import annotations

import tempfile
import time
from pathlib import Path

from harness import Context, alternating, case
from harness.proctree import become_subreaper, self_and_tree_cpu_s

__all__ = ["idle_cost", "instant", "make_sweep", "sweep_engine", "sweep_throughput", "time_cluster", "time_figures",
           "time_plain", "time_sweep"]

#: the arms of ``sweep_throughput``
SWEEP_ARMS = ("sweep1", "plain", "sweep2", "first")


def make_sweep(ctx: Context, n: int, duration: float, ground_truth: bool = True, run_figures: bool = True):
    """A Sweep of ``n`` default runs (seeds 0..n-1) of ``duration`` s: ground truth without a renderer, or
    perception feedback; ``run_figures``: each run writes its figures."""
    from cosim.studies.sweepfile import RunSpec, Sweep, run_id

    extra = {"duration_s": duration, **({"renderer": "none", "feedback": "ground_truth"} if ground_truth else {})}
    if not run_figures:
        extra["outputs"] = {"figures": False}
    runs = []
    for seed in range(n):
        sc = ctx.scenario("default", extra={**extra, "seed": seed})
        runs.append(RunSpec(run_id("default", {"duration_s": duration}, {}, seed), {}, seed, sc))
    return Sweep("bench", (), tuple(runs))


def _steady(runs_dir: Path) -> float | None:
    """Seconds per run between the first and the last run's summary.json (None for one run)."""
    t = sorted(p.stat().st_mtime_ns for p in runs_dir.glob("*/summary.json"))
    return (t[-1] - t[0]) / 1e9 / (len(t) - 1) if len(t) > 1 else None


def time_sweep(sweep, jobs: int, runner=None) -> tuple[float, float | None, float]:
    """(wall s, steady s per run, CPU s of this process and its descendants) of ``run_sweep`` with ``jobs`` local
    workers; raises where a run did not complete."""
    from cosim.studies.sweep import run_sweep

    become_subreaper()
    with tempfile.TemporaryDirectory(prefix="bench-sweep-") as tmp:
        t, c = time.perf_counter(), self_and_tree_cpu_s()
        kw = {"runner": runner} if runner is not None else {}
        out = run_sweep(sweep, Path(tmp), jobs=jobs, quiet=True, figures=False, **kw)
        wall, used = time.perf_counter() - t, self_and_tree_cpu_s() - c
        if out.completed != len(sweep.runs):
            raise RuntimeError(f"sweep with {jobs} workers completed {out.completed} of {len(sweep.runs)} runs")
        return wall, _steady(Path(tmp) / "runs"), used


def time_plain(sweep) -> tuple[float, float | None, float]:
    """The same as :func:`time_sweep` for a plain loop of ``launch()`` calls in this process."""
    from cosim.runtime.launcher import launch

    become_subreaper()
    with tempfile.TemporaryDirectory(prefix="bench-sweep-") as tmp:
        (Path(tmp) / "runs").mkdir()
        t, c = time.perf_counter(), self_and_tree_cpu_s()
        for run in sweep.runs:
            if not launch(run.scenario, Path(tmp) / "runs" / run.id, console_log=False).completed:
                raise RuntimeError(f"run {run.id} did not complete")
        return time.perf_counter() - t, _steady(Path(tmp) / "runs"), self_and_tree_cpu_s() - c


def time_cluster(jobs: int) -> float:
    """Wall s of an embedded cluster's start-up and shut-down."""
    from cosim.studies.sweep import open_client

    t = time.perf_counter()
    with open_client(None, jobs, False):
        pass
    return time.perf_counter() - t


def time_figures(n: int) -> float:
    """Wall s of the sweep figures of ``n`` results."""
    from cosim.studies.figures import write_sweep_figures

    with tempfile.TemporaryDirectory() as tmp:
        rows = [{"seed": s, "completed": True, "wall_time_s": 1.0 + s} for s in range(n)]
        t = time.perf_counter()
        write_sweep_figures(Path(tmp), rows, ())
        return time.perf_counter() - t


@case("sweep_throughput", "launch.py sweep: runs per hour with 1 and 2 local workers, the engine's overhead per run "
      "against a plain launch() loop", options={"runs": 6, "duration": 60.0, "feedback": "ground_truth",
                                                 "arms": ",".join(SWEEP_ARMS), "run_figures": True},
      quick={"runs": 2, "duration": 1.0, "arms": "sweep1,plain,first"}, rounds=3, settings=True,
      compare=("wall per run s", "CPU per run s"))
def sweep_throughput(ctx: Context) -> dict:
    """Every arm of ``arms`` (comma-separated, of sweep1, plain, sweep2, first) on the same runs (module docstring)."""
    arms = ctx["arms"].split(",")
    unknown = set(arms) - set(SWEEP_ARMS)
    if unknown:
        raise ValueError(f"unknown arms {sorted(unknown)}; choose from {', '.join(SWEEP_ARMS)}")
    n = ctx["runs"]
    sweep = make_sweep(ctx, n, ctx["duration"], ctx["feedback"] == "ground_truth", ctx["run_figures"])
    first = type(sweep)(sweep.name, sweep.parameters, sweep.runs[:1])
    steps = {"sweep1": lambda: time_sweep(sweep, 1), "plain": lambda: time_plain(sweep),
             "sweep2": lambda: time_sweep(sweep, 2), "first": lambda: time_sweep(first, 1)}
    got = {a: steps[a]() for a in alternating(arms, ctx.round)}
    rows = {}
    for a in arms:
        wall, steady, cpu = got[a]
        k = 1 if a == "first" else n
        rows[a] = {"wall per run s": wall / k, "runs per hour (all in)": 3600.0 * k / wall,
                   "steady state per run s": steady, "CPU per run s": cpu / k}
    out = {f"{n} runs of {ctx['duration']:g} s ({ctx['feedback']})": rows}
    derived = {}
    if {"sweep1", "first"} <= set(got) and n > 1:
        derived["sweep1 per run at the margin, (sweep1 - first) / (N - 1)"] = {
            "wall s": (got["sweep1"][0] - got["first"][0]) / (n - 1), "CPU s": (got["sweep1"][2] - got["first"][2]) / (n - 1)}
    if {"sweep1", "plain"} <= set(got):
        plain_wall, plain_cpu = got["plain"][0] / n, got["plain"][2] / n
        derived["sweep1 overhead against plain, all in (%)"] = {
            "wall s": 100 * (got["sweep1"][0] / n / plain_wall - 1), "CPU s": 100 * (got["sweep1"][2] / n / plain_cpu - 1)}
        if "first" in got and n > 1:
            m = derived["sweep1 per run at the margin, (sweep1 - first) / (N - 1)"]
            derived["sweep1 overhead against plain, at the margin (%)"] = {
                "wall s": 100 * (m["wall s"] / plain_wall - 1), "CPU s": 100 * (m["CPU s"] / plain_cpu - 1)}
            derived["fixed cost of a sweep (first less one plain run)"] = {
                "wall s": got["first"][0] - plain_wall, "CPU s": got["first"][2] - plain_cpu}
        derived["cluster start-up and shut-down (1 worker)"] = {"wall s": time_cluster(1)}
        derived["sweep figures"] = {"wall s": time_figures(n)}
    if {"sweep1", "sweep2"} <= set(got):
        derived["2 workers / 1 worker, runs per hour"] = {"ratio": got["sweep1"][0] / got["sweep2"][0]}
    if derived:
        out["derived"] = derived
    return out


def instant(run_dir: str, scenario_json: str) -> dict:
    """A sweep runner that runs nothing: a completed summary with the metrics' keys."""
    return {"summary": {"completed": True, "fill": {"profile_rmse_m": 0.5}, "real_time_factor": 15.0},
            "error": "", "worker": "bench"}


def idle_cost(seconds: float) -> float:
    """CPU s per second of an idle embedded cluster (1 worker), less an open-close with no wait."""
    from cosim.studies.sweep import open_client

    become_subreaper()
    c = self_and_tree_cpu_s()
    with open_client(None, 1, False):
        time.sleep(seconds)
    with_wait = self_and_tree_cpu_s() - c
    c = self_and_tree_cpu_s()
    with open_client(None, 1, False):
        pass
    return (with_wait - (self_and_tree_cpu_s() - c)) / seconds


@case("sweep_engine", "the sweep engine's own cost per run with the run taken out, and the idle cluster's CPU",
      options={"tasks": 60, "idle": 10.0}, quick={"tasks": 3, "idle": 0.5}, rounds=3)
def sweep_engine(ctx: Context) -> dict:
    """``tasks`` instant runs against 1, order alternating by round, then the idle cluster (module docstring)."""
    many = make_sweep(ctx, ctx["tasks"], 60.0)
    one = type(many)(many.name, (), many.runs[:1])
    got = {k: time_sweep(s, 1, runner=instant) for k, s in alternating([("many", many), ("one", one)], ctx.round)}
    n = ctx["tasks"] - 1
    return {"engine": {"per run": {"wall ms": 1e3 * (got["many"][0] - got["one"][0]) / n,
                                   "CPU ms": 1e3 * (got["many"][2] - got["one"][2]) / n}},
            "idle embedded cluster": {"per second": {"CPU ms": 1e3 * idle_cost(ctx["idle"])}}}
