"""How a perception run's cost grows: CPU per frame against beams and against the grain grid, and sweep
throughput with 1 and 2 local workers; each curve measured side by side in one run.

* **Beams**: the default scenario with its LiDAR pattern (the honeycomb over the same 90 x 95 deg field) at
  several densities, 10,000 to 300,000 beams, the 128 x 2048 pattern (128 elevation rows, 2,048 azimuth
  columns) among them. One in-process session per
  point (``cosim.runtime.inprocess``: the launched run's participants and blocks, GL renderer), all open at once
  and stepped frame by frame in rotating order, so that every point sees the same machine; CPU per frame of each
  ring member's step (process CPU over the step: llvmpipe's threads included), medians over ``--frames`` after
  ``--warmup``. The cost per beam is the slope of a least-squares line through the points (renderer, perception,
  both).
* **Grain grid**: the same with ``grain.cell_m`` 0.1 to 0.025 m (cells per cart 1,800 to 28,800).
* **Sweep throughput**: ``launch.py sweep``'s engine (``cosim.studies.sweep.run_sweep``) over ``--runs`` default
  perception runs of ``--sweep-duration`` s, with 1 and with 2 local workers, rounds interleaved: runs per hour all
  in (cluster start-up included) and the CPU per run of the whole process tree (this process the subreaper of
  its descendants, ``bench/proctree.py``).
* **Sensors**: one sensor per run until several sensors (and cameras) can be named in a scenario; the curve
  against 1 to 4 sensors is left out and says so.

Usage::

    python bench/curves.py                 # every curve (several minutes)
    python bench/curves.py --only beams --frames 60
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from proctree import become_subreaper, reap, tree_cpu_s  # noqa: E402

__all__ = ["BEAM_POINTS", "CELL_POINTS", "beams_curve", "cells_curve", "sweep_curve", "fit_per_unit", "main"]

#: (label, azimuth_count, elevation_count) of the beam curve: the default field at these densities
BEAM_POINTS = (("100 x 100", 100, 100), ("240 x 160 (the default)", 240, 160), ("400 x 250", 400, 250),
               ("2048 x 128 (the 128 x 2048 pattern)", 2048, 128), ("600 x 500", 600, 500))
#: grain cells of the grid curve, m
CELL_POINTS = (0.1, 0.075, 0.05, 0.025)
MEMBERS = ("dynamics", "renderer", "perception")
SENSORS_NOTE = ("Not measured: a scenario has one LiDAR until several sensors (and cameras) can be named in it; "
                "this curve is to be added then.")


def _scenario(**extra):
    from cosim.scenario.loader import load_scenario, resolve_scenario_arg

    return load_scenario(resolve_scenario_arg("default"), extra=extra)


def _interleaved(scenarios: dict[str, object], frames: int, warmup: int) -> dict[str, dict[str, float]]:
    """Median CPU ms per frame of each member's step, per labelled scenario, all sessions stepped in turn."""
    from cosim.runtime.heap import keep_heap
    from cosim.runtime.inprocess import InProcessSession

    keep_heap()
    sessions, cpu = {}, {}
    try:
        for label, sc in scenarios.items():
            sess = InProcessSession(sc, frames=warmup + frames)
            sessions[label] = sess
            cpu[label] = {m: [] for m in sess.participants}
            for name, p in sess.participants.items():
                step, into = p.step, cpu[label][name]

                def timed(frame, step=step, into=into):
                    c = time.process_time()
                    rest = step(frame)
                    own = time.process_time() - c
                    if rest is None:
                        into.append(own)
                        return None

                    def timed_rest(rest=rest, own=own):
                        c2 = time.process_time()
                        rest()
                        into.append(own + time.process_time() - c2)
                    return timed_rest
                p.step = timed
        labels = list(sessions)
        for k in range(warmup + frames + 1):
            for label in labels[k % len(labels):] + labels[:k % len(labels)]:
                sessions[label].step()
    finally:
        for sess in sessions.values():
            sess.close()
    out = {}
    for label, per in cpu.items():
        out[label] = {m: 1e3 * statistics.median(v[warmup:]) for m, v in per.items() if len(v) > warmup}
        out[label]["total"] = sum(out[label].values())
    return out


def fit_per_unit(xs: list[float], ys: list[float]) -> tuple[float, float]:
    """(slope, intercept) of the least-squares line y = slope x + intercept."""
    n = len(xs)
    mx, my = sum(xs) / n, sum(ys) / n
    sxx = sum((x - mx) ** 2 for x in xs)
    slope = sum((x - mx) * (y - my) for x, y in zip(xs, ys)) / sxx if sxx else float("nan")
    return slope, my - slope * mx


def beams_curve(frames: int, warmup: int, points=BEAM_POINTS) -> dict:
    """CPU ms per frame of each member at each beam count; ns per beam (slopes)."""
    scenarios, beams = {}, {}
    for label, az, el in points:
        scenarios[label] = _scenario(sensor={"pattern": {"azimuth_count": az, "elevation_count": el}})
        beams[label] = az * el
    res = _interleaved(scenarios, frames, warmup)
    xs = [beams[k] for k in res]
    slopes = {m: 1e6 * fit_per_unit(xs, [res[k][m] for k in res])[0] for m in ("renderer", "perception", "total")}
    return {"points": [{"label": k, "beams": beams[k], **res[k]} for k in res], "ns_per_beam": slopes}


def cells_curve(frames: int, warmup: int, points=CELL_POINTS) -> dict:
    """CPU ms per frame of each member at each grain cell size; us per cell (slopes)."""
    scenarios, cells = {}, {}
    for cell in points:
        sc = _scenario(grain={"cell_m": cell})
        label = f"{cell:g} m"
        scenarios[label] = sc
        cells[label] = sc.cart.grid_shape(cell)[0] * sc.cart.grid_shape(cell)[1]
    res = _interleaved(scenarios, frames, warmup)
    xs = [cells[k] for k in res]
    slopes = {m: 1e3 * fit_per_unit(xs, [res[k][m] for k in res])[0] for m in (*MEMBERS, "total")}
    return {"points": [{"label": k, "cells": cells[k], **res[k]} for k in res], "us_per_cell": slopes}


def sweep_curve(runs: int, duration: float, rounds: int) -> dict:
    """Runs per hour and CPU per run of a sweep of default perception runs with 1 and 2 local workers."""
    import resource

    from cosim.studies.sweep import run_sweep
    from cosim.studies.sweepfile import RunSpec, Sweep, run_id

    specs = []
    for seed in range(runs):
        sc = _scenario(duration_s=duration, seed=seed, outputs={"figures": False})
        specs.append(RunSpec(run_id("default", {"duration_s": duration}, {}, seed), {}, seed, sc))
    sweep = Sweep("curves", (), tuple(specs))

    def cpu() -> float:
        reap()                                   # the workers' and their runs' processes, orphaned or not
        me = resource.getrusage(resource.RUSAGE_SELF)
        return me.ru_utime + me.ru_stime + tree_cpu_s()

    become_subreaper()

    out = {1: [], 2: []}
    for r in range(rounds):
        for jobs in ((1, 2) if r % 2 == 0 else (2, 1)):
            with tempfile.TemporaryDirectory(prefix="curves-sweep-") as tmp:
                t, c = time.perf_counter(), cpu()
                res = run_sweep(sweep, Path(tmp), jobs=jobs, quiet=True, figures=False)
                wall, used = time.perf_counter() - t, cpu() - c
            if res.completed != runs:
                raise RuntimeError(f"sweep with {jobs} workers completed {res.completed} of {runs} runs")
            out[jobs].append((wall, used))
    return {"runs": runs, "duration_s": duration, "rounds": rounds, "workers": {
        str(j): {"runs_per_hour": 3600.0 * runs / statistics.median(w for w, _ in v),
                 "cpu_s_per_run": statistics.median(c for _, c in v) / runs} for j, v in out.items()}}


def render_markdown(res: dict) -> str:
    """The curves as Markdown sections (bench/results.md)."""
    lines = []
    b = res.get("beams")
    if b:
        lines += ["### CPU per frame against beams (GL, the default pattern's field at other densities, interleaved in "
                  "one process)", "",
                  "| pattern (azimuth x elevation) | beams | dynamics ms | renderer ms | perception ms | total ms |",
                  "|---|---:|---:|---:|---:|---:|"]
        for p in b["points"]:
            lines.append(f"| {p['label']} | {p['beams']:,} | {p.get('dynamics', 0):.2f} | {p.get('renderer', 0):.2f} "
                         f"| {p.get('perception', 0):.2f} | {p['total']:.2f} |")
        s = b["ns_per_beam"]
        lines += ["", f"Cost per beam (slope of a least-squares line): renderer {s['renderer']:.1f} ns, perception "
                      f"{s['perception']:.1f} ns, all members {s['total']:.1f} ns of CPU per beam and frame.", ""]
    c = res.get("cells")
    if c:
        lines += ["### CPU per frame against the grain grid (`grain.cell_m`)", "",
                  "| cell | cells | dynamics ms | renderer ms | perception ms | total ms |", "|---|---:|---:|---:|---:|---:|"]
        for p in c["points"]:
            lines.append(f"| {p['label']} | {p['cells']:,} | {p.get('dynamics', 0):.2f} | {p.get('renderer', 0):.2f} "
                         f"| {p.get('perception', 0):.2f} | {p['total']:.2f} |")
        u = c["us_per_cell"]
        lines += ["", f"Cost per cell (slope): dynamics {u['dynamics']:.2f} us, renderer {u['renderer']:.2f} us, "
                      f"perception {u['perception']:.2f} us, all {u['total']:.2f} us of CPU per cell and frame.", ""]
    s = res.get("sweep")
    if s:
        w = s["workers"]
        lines += [f"### Sweep throughput (`launch.py sweep`'s engine, {s['runs']} default perception runs of "
                  f"{s['duration_s']:g} s, {s['rounds']} interleaved rounds)", "",
                  "| local workers | runs per hour (all in) | CPU per run (s, process tree) |", "|---:|---:|---:|"]
        for j in ("1", "2"):
            lines.append(f"| {j} | {w[j]['runs_per_hour']:.0f} | {w[j]['cpu_s_per_run']:.2f} |")
        lines += ["", f"2 workers / 1 worker: {w['2']['runs_per_hour'] / w['1']['runs_per_hour']:.2f}x runs per "
                      "hour.", ""]
    lines += ["### CPU per frame against sensors", "", SENSORS_NOTE, ""]
    return "\n".join(lines)


def measure(only: tuple[str, ...] = ("beams", "cells", "sweep"), frames: int = 60, warmup: int = 100,
            runs: int = 4, sweep_duration: float = 20.0, rounds: int = 2, quick: bool = False) -> dict:
    """Every curve asked for (``only``); ``quick``: two points each and a tiny sweep (checks the script)."""
    res: dict = {"sensors": SENSORS_NOTE}
    if "beams" in only:
        res["beams"] = beams_curve(frames, warmup, BEAM_POINTS[:2] if quick else BEAM_POINTS)
    if "cells" in only:
        res["cells"] = cells_curve(frames, warmup, CELL_POINTS[::2] if quick else CELL_POINTS)
    if "sweep" in only:
        res["sweep"] = sweep_curve(runs, sweep_duration, rounds)
    return res


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", default="beams,cells,sweep", help="comma-separated: beams, cells, sweep")
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--warmup", type=int, default=100, help="frames before the measured ones (the cart in view, "
                    "the auger on)")
    ap.add_argument("--runs", type=int, default=4, help="runs per sweep")
    ap.add_argument("--sweep-duration", type=float, default=20.0)
    ap.add_argument("--rounds", type=int, default=2, help="interleaved rounds of the sweeps")
    a = ap.parse_args(argv)
    res = measure(tuple(a.only.split(",")), a.frames, a.warmup, a.runs, a.sweep_duration, a.rounds)
    print(f"{os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}\n")
    print(render_markdown(res))
    print(json.dumps(res))
    return res


if __name__ == "__main__":
    main()
