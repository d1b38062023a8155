"""The sweep engine's own cost per run, apart from the runs: companion of sweep_throughput.py.

Run from the repository root::

    nice -n 5 python bench/sweep_engine_cost.py --tasks 60 --rounds 3 --idle 10

On a loaded machine the runs' own time varies by more than the engine costs, so this measures the engine with
the run taken out. Per round, interleaved: a sweep of ``--tasks`` runs whose runner returns a completed summary
at once (everything else as in a real sweep: 1 local worker, submit, scheduling, result transfer, the results
table rewritten after each run) and the same with 1 task; the difference over tasks - 1 is the engine's cost per
run, wall and CPU (this process and its reaped descendants). Then the embedded cluster idles ``--idle`` seconds:
the CPU its processes use per second while a run goes (heartbeats, monitors), minus an open-close with no wait.
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

from cosim.studies.sweep import open_client, run_sweep  # noqa: E402
from cosim.studies.sweepfile import Sweep  # noqa: E402

sys.path.insert(0, str(ROOT / "bench"))
from sweep_throughput import make_sweep  # noqa: E402


def instant(run_dir: str, scenario_json: str) -> dict:
    """A runner that runs nothing: a completed summary with the metrics' keys."""
    return {"summary": {"completed": True, "fill": {"profile_rmse_m": 0.5}, "real_time_factor": 15.0},
            "error": "", "worker": "bench"}


def cpu() -> float:
    me, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


def sweep_cost(sweep: Sweep) -> tuple[float, float]:
    with tempfile.TemporaryDirectory(prefix="sweepcost-") as tmp:
        t, c = time.perf_counter(), cpu()
        out = run_sweep(sweep, Path(tmp), jobs=1, quiet=True, runner=instant, figures=False)
        assert out.completed == len(sweep.runs)
        return time.perf_counter() - t, cpu() - c


def idle_cost(seconds: float) -> float:
    c = cpu()
    with open_client(None, 1, False):
        time.sleep(seconds)
    with_wait = cpu() - c
    c = cpu()
    with open_client(None, 1, False):
        pass
    return (with_wait - (cpu() - c)) / seconds


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--tasks", type=int, default=60)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--idle", type=float, default=10.0)
    args = ap.parse_args()
    many = make_sweep(args.tasks, 60.0)
    one = Sweep(many.name, (), many.runs[:1])
    wall, cpus, idle = [], [], []
    for r in range(args.rounds):
        pair = [sweep_cost(many), sweep_cost(one)] if r % 2 == 0 else [sweep_cost(one), sweep_cost(many)][::-1]
        (wm, cm), (w1, c1) = pair
        wall.append((wm - w1) / (args.tasks - 1))
        cpus.append((cm - c1) / (args.tasks - 1))
        idle.append(idle_cost(args.idle))
        print(f"round {r + 1}: {wall[-1] * 1000:.1f} ms wall, {cpus[-1] * 1000:.1f} ms CPU per run; idle "
              f"{idle[-1] * 1000:.1f} ms CPU per s", file=sys.stderr)
    print(f"engine cost per run (medians of {args.rounds} rounds, min-max): "
          f"{statistics.median(wall) * 1000:.1f} ms wall ({min(wall) * 1000:.1f}-{max(wall) * 1000:.1f}), "
          f"{statistics.median(cpus) * 1000:.1f} ms CPU ({min(cpus) * 1000:.1f}-{max(cpus) * 1000:.1f}); "
          f"the idle cluster uses {statistics.median(idle) * 1000:.1f} ms CPU per second "
          f"({min(idle) * 1000:.1f}-{max(idle) * 1000:.1f})")


if __name__ == "__main__":
    main()
