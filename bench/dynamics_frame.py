"""Cost of one dynamics frame (0.1 s, 10 internal steps) and of its parts, at grain cells of 0.1 and 0.05 m.

Runs the default ground-truth fill (front-to-back, half full to 1.9 m) through the pure frame step and times
every frame; separately times the parts on the same states: vehicles + Machine Sync (10 held-input steps),
stream and first surface, grain deposit, controller (estimate, strategy, nudges), signals. Also the closed-loop
real-time factor (simulated s per wall s, frame step + truth measurement + signals).

Run: ``python bench/dynamics_frame.py`` (prints Markdown tables).
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from cosim.scenario.config import Scenario  # noqa: E402
from dynamics_proc import auger as ag  # noqa: E402
from dynamics_proc.closed_loop import simulate  # noqa: E402
from dynamics_proc.controller import Delivery, controller_step  # noqa: E402
from dynamics_proc.grainfill import deposit  # noqa: E402
from dynamics_proc.integrators import integrate  # noqa: E402
from dynamics_proc.machine_sync import sync_command  # noqa: E402
from dynamics_proc.model import ModelParams, initial_world, signals, spout_grid, step_frame, truth_measurement  # noqa: E402

FRAMES = 900


def scenario(cell: float, method: str = "exponential") -> Scenario:
    return Scenario.model_validate({"format_version": 1, "feedback": "ground_truth", "renderer": "none",
                                    "grain": {"cell_m": cell}, "controller": {"grid_cell_m": 0.1},
                                    "integrator": {"method": method}})


def frame_costs(s: Scenario) -> dict[str, np.ndarray]:
    p = ModelParams.from_scenario(s)
    w = initial_world(s, p)
    hist = {0: truth_measurement(w.heights, p)}
    parts: dict[str, list[float]] = {k: [] for k in ("frame", "vehicles", "stream", "deposit", "controller",
                                                      "measure+signals")}
    for m in range(1, FRAMES + 1):
        meas = hist.pop(m - 2, None)
        # parts, on the state this frame starts from
        t0 = time.perf_counter()
        x = w.x
        for _ in range(p.steps):
            x = integrate(p.method, x, sync_command(x, w.setpoint, p.vehicles, p.gains), p.vehicles, p.dt_s)
        t1 = time.perf_counter()
        sp, vel, spg, g = spout_grid(x, p)
        imp = ag.first_surface(sp, vel, g, w.heights, p.grid.cell_m, p.auger)
        ag.stream_rows(sp, vel, imp.time_s, 0.15)
        t2 = time.perf_counter()
        if imp.surface == ag.SURFACE_GRAIN:
            deposit(w.heights, float(imp.grid[0]), float(imp.grid[1]), 0.0125, p.grid, p.cap)
        t3 = time.perf_counter()
        delivery = Delivery(w.delivered_m3, spg, g[:3, :3] @ vel) if p.control.fusion is not None else None
        controller_step(w.ctrl, p.control, w.t_s, meas, float(spg[0]), ((1.0, 1.0), (1.0, 1.0)), 0.0, 0.35,
                        delivery)
        t4 = time.perf_counter()
        # the real frame
        w = step_frame(w, meas, p)
        t5 = time.perf_counter()
        hist[m] = truth_measurement(w.heights, p)
        signals(w, p)
        t6 = time.perf_counter()
        for k, v in zip(parts, (t5 - t4, t1 - t0, t2 - t1, t3 - t2, t4 - t3, t6 - t5)):
            parts[k].append(v * 1e3)
    return {k: np.array(v) for k, v in parts.items()}


def main() -> None:
    print("| grain cell | cells | part | median ms | p95 ms |")
    print("|---|---|---|---|---|")
    for cell in (0.1, 0.05):
        s = scenario(cell)
        c = frame_costs(s)
        n = round(6.0 / cell) * round(3.0 / cell)
        for k, v in c.items():
            print(f"| {cell:g} m | {n} | {k} | {np.median(v):.3f} | {np.percentile(v, 95):.3f} |")
    print()
    print("| grain cell | integrator | frames | sim s | wall s | real-time factor |")
    print("|---|---|---|---|---|---|")
    for cell in (0.1, 0.05):
        for method in ("exponential", "rk4"):
            s = scenario(cell, method)
            r = simulate(s, FRAMES)
            sim = FRAMES * s.timing.sensor_period_s
            print(f"| {cell:g} m | {method} | {FRAMES} | {sim:g} | {r.wall_s:.2f} | {sim / r.wall_s:.0f} |")


if __name__ == "__main__":
    main()
