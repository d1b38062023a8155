"""The dynamics process: the cost of a frame and of its parts, the integration methods' error against run time, and
the fill strategies compared.

``dynamics_frame``: the default ground-truth fill (front-to-back, half full to 1.9 m) through the pure frame step,
every frame timed, at grain cells of 0.1 and 0.05 m; separately the parts on the same states: vehicles + Machine
Sync (the frame's held-input steps), stream and first surface, grain deposit, controller, signals; and the
closed-loop real-time factor (frame step + truth measurement + signals) with each integrator.

``integrators``: the vehicle model under Machine Sync, the controller sampled once per 0.1 s frame (zero-order hold),
every method integrating the same held-input problem over the frame: RK4 and the exponential method with 1..50
substeps, solve_ivp Radau and BDF at several tolerances; reference Radau at rtol 1e-12. Arc path (R = 60 m), initial
offsets 1 m / -0.5 m and a +0.3 m nudge every 4 s, ``sim_s`` simulated; default drivetrain (tau 0.5 s) and stiff
(1 ms). Error: the largest cart position deviation from the reference; cost: wall ms per simulated s.

``strategies``: the fill strategies on the default cart, ground truth and a perceived stand-in (the truth on the
controller grid through 30 % random holes and 2 cm Gaussian noise, seeded): time to target, peak error, profile
RMSE, fill fraction, spill, nudges, and the levelness (spread of the section means) when half the grain is in.
"""
from __future__ import annotations

import math
import time

from harness import Context, case

__all__ = ["dynamics_frame", "frame_costs", "integrators", "strategies"]

#: integrator study: frame, nudge period and size
FRAME_S, NUDGE_EVERY_S, NUDGE_M = 0.1, 4.0, 0.3
#: the perceived stand-in of ``strategies``: share of cells lost, noise sigma (m)
HOLES, SIGMA_M = 0.3, 0.02


def _ground_truth(ctx: Context, **extra):
    return ctx.scenario("default", extra={"feedback": "ground_truth", "renderer": "none", **extra})


def frame_costs(s, frames: int) -> dict:
    """ms per frame (arrays over frames) of the whole frame step and of its parts, on the states of a run."""
    import numpy as np

    from dynamics_proc.control.controller import Delivery, controller_step
    from dynamics_proc.control.protocol import ControllerInput
    from dynamics_proc.grain import auger as ag
    from dynamics_proc.grain.fill import deposit
    from dynamics_proc.model import ModelParams, initial_world, signals, spout_grid, step_frame, truth_measurement
    from dynamics_proc.vehicles.integrators import integrate
    from dynamics_proc.vehicles.machine_sync import sync_command

    p = ModelParams.from_scenario(s)
    w = initial_world(s, p)
    hist = {0: truth_measurement(w.heights, p)}
    parts: dict[str, list[float]] = {k: [] for k in ("frame", "vehicles", "stream", "deposit", "controller",
                                                      "measure+signals")}
    for m in range(1, frames + 1):
        meas = hist.pop(m - 2, None)
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
        controller_step(w.ctrl, p.control, ControllerInput(
            t_s=w.t_s, frame=m, heights=meas, spout_x_m=float(spg[0]), impacts=((1.0, 1.0), (1.0, 1.0)), drift_x_m=0.0,
            nudge_signal_m=0.35, delivery=delivery, target_fill_m=p.control.target_m))
        t4 = time.perf_counter()
        w = step_frame(w, meas, p)
        t5 = time.perf_counter()
        hist[m] = truth_measurement(w.heights, p)
        signals(w, p)
        t6 = time.perf_counter()
        for k, v in zip(parts, (t5 - t4, t1 - t0, t2 - t1, t3 - t2, t4 - t3, t6 - t5)):
            parts[k].append(v * 1e3)
    return {k: np.array(v) for k, v in parts.items()}


@case("dynamics_frame", "one dynamics frame's cost and its parts at two grain cells; closed-loop real-time factor",
      options={"frames": 900, "cells": "0.1,0.05"}, quick={"frames": 10, "cells": "0.1"}, settings=True)
def dynamics_frame(ctx: Context) -> dict:
    """Median and p95 ms per part of a frame; the real-time factor of the closed loop (module docstring)."""
    import numpy as np

    from dynamics_proc.closed_loop import simulate

    frames, cells = ctx["frames"], [float(c) for c in str(ctx["cells"]).split(",")]
    parts, loops = {}, {}
    for cell in cells:
        s = _ground_truth(ctx, grain={"cell_m": cell}, controller={"grid_cell_m": 0.1})
        n = s.cart.grid_shape(cell)[0] * s.cart.grid_shape(cell)[1]
        for k, v in frame_costs(s, frames).items():
            parts[f"{cell:g} m ({n} cells), {k}"] = {"median ms": float(np.median(v)), "p95 ms": float(np.percentile(v, 95))}
        for method in ("exponential", "rk4"):
            s = _ground_truth(ctx, grain={"cell_m": cell}, controller={"grid_cell_m": 0.1},
                              integrator={"method": method})
            r = simulate(s, frames)
            sim = frames * s.timing.sensor_period_s
            loops[f"{cell:g} m, {method}"] = {"sim s": sim, "wall s": r.wall_s, "real-time factor": sim / r.wall_s}
    return {f"parts of a frame ({frames} frames)": parts, "closed loop (frame step, truth measurement, signals)": loops}


def _integrate_run(s, method: str, sim_s: float, substeps: int = 1, rtol: float = 1e-8, atol: float = 1e-10):
    """Cart positions (frames + 1, 2) m and wall s of the Machine Sync closed loop with ``method``."""
    import numpy as np

    from dynamics_proc.vehicles.integrators import integrate
    from dynamics_proc.vehicles.machine_sync import SyncGains, sync_command
    from dynamics_proc.vehicles.motion import VehicleParams, cart_pose, initial_state

    p, g = VehicleParams.from_scenario(s), SyncGains.from_scenario(s)
    x = initial_state(s, p)
    sp = [s.machine_sync.longitudinal_offset_m, s.machine_sync.lateral_offset_m]
    frames = round(sim_s / FRAME_S)
    out = np.empty((frames + 1, 2))
    out[0] = cart_pose(x, p)[:2]
    t0 = time.perf_counter()
    for m in range(1, frames + 1):
        if (m - 1) % round(NUDGE_EVERY_S / FRAME_S) == 0 and m > 1:
            sp[0] += NUDGE_M
        x = integrate(method, x, sync_command(x, tuple(sp), p, g), p, FRAME_S, substeps, rtol, atol)
        out[m] = cart_pose(x, p)[:2]
    return out, time.perf_counter() - t0


@case("integrators", "each integration method's error against run time on the vehicle model (default and stiff "
      "drivetrain)", options={"sim_s": 20.0, "substeps": "1,2,5,10,50", "rtols": "1e-3,1e-6,1e-9"},
      quick={"sim_s": 1.0, "substeps": "1,10", "rtols": "1e-3"})
def integrators(ctx: Context) -> dict:
    """Every method and step or tolerance at both drivetrain time constants (module docstring)."""
    import numpy as np

    rows = {}
    for tau in (0.5, 0.001):
        s = ctx.scenario("default", extra={
            "feedback": "ground_truth", "renderer": "none", "combine": {"path": "arc", "path_radius_m": 60.0},
            "tractor": {"drivetrain_tau_s": tau},
            "machine_sync": {"initial_long_error_m": 1.0, "initial_lat_error_m": -0.5}})
        ref, _ = _integrate_run(s, "radau", ctx["sim_s"], rtol=1e-12, atol=1e-12)
        subs = [int(n) for n in str(ctx["substeps"]).split(",")]
        runs = [(m, n, None) for m in ("rk4", "exponential") for n in subs]
        runs += [(m, 1, float(r)) for m in ("radau", "bdf") for r in str(ctx["rtols"]).split(",")]
        for method, n, rtol in runs:
            kw = {"rtol": rtol, "atol": rtol * 1e-2} if rtol else {}
            pos, wall = _integrate_run(s, method, ctx["sim_s"], n, **kw)
            err = float(np.max(np.hypot(*(pos - ref).T))) if np.all(np.isfinite(pos)) else math.inf
            step = f"{FRAME_S / n * 1e3:g} ms" if rtol is None else f"rtol {rtol:g}"
            rows[f"tau {tau:g} s, {method}, {step}"] = {"max cart position error m": err,
                                                       "wall ms per simulated s": wall / ctx["sim_s"] * 1e3}
    return {"integration methods": rows}


@case("strategies", "the fill strategies compared on the default cart, ground truth and a perceived stand-in",
      options={"duration": 300.0, "strategies": "front_to_back,back_to_front,lowest_first", "feedbacks": "truth,perceived"},
      quick={"duration": 20.0, "strategies": "front_to_back", "feedbacks": "truth"})
def strategies(ctx: Context) -> dict:
    """Each strategy with each feedback, run until the cart is full (module docstring)."""
    import numpy as np

    from dynamics_proc.closed_loop import noisy_measurement, simulate
    from dynamics_proc.summary import section_stats, summarize

    rows = {}
    for feedback in ctx["feedbacks"].split(","):
        for strategy in ctx["strategies"].split(","):
            s = _ground_truth(ctx, duration_s=ctx["duration"], controller={"strategy": strategy})
            measure = noisy_measurement(7, HOLES, SIGMA_M) if feedback == "perceived" else None
            r = simulate(s, stop_when_done=True, measure=measure)
            f = summarize(s, r.series, r.heights)
            fill = f["fill"]
            row = {"time to target s": fill["time_to_target_s"],
                   "peak error max cm": 100 * float(np.max(np.abs(np.array(fill["section_peak_height_m"])
                                                                  - fill["target_height_m"]))),
                   "profile RMSE cm": 100 * fill["profile_rmse_m"], "fill fraction": fill["fill_fraction"],
                   "spill kg": f["spill"]["mass_kg"], "nudges": f["controller"]["nudges"]}
            if feedback == "truth":
                d = r.series["dyn_state.delivered_m3"]
                _, mean = section_stats(simulate(s, int(np.searchsorted(d, 0.5 * d[-1]))).heights, s)
                row["levelness at 50 % cm"] = 100 * float(mean.max() - mean.min())
            rows[f"{feedback}, {strategy}"] = row
    return {"fill strategies": rows}
