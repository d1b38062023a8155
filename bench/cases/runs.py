"""Whole runs in-process: the extreme packaged scenarios with perception in the loop, the Python API's cost per
frame, and FMUs in the loop against the built-in models.

``extreme``: the stiff and extreme packaged scenarios run to the end, in process, with the GL renderer and their
packaged settings (fused estimator unless ``estimator=paper``): fill (max overfill above target, profile RMSE,
spill), time to target, nudges, perception (cart found, height-map RMSE and coverage) and wall time. The metrics
do not depend on the machine's load (the loop is deterministic); the wall times do.

``api_overhead``: the default scenario (ground-truth feedback, no renderer: the cheapest frame, so the API's own cost
shows most) run whole in this process as ``simulate(s)``, as ``Simulation(s)`` stepped one frame per ``step()`` (each
step takes a state snapshot) and ten frames per call, in rotating order after a warm-up of each: wall ms per frame
(set-up included).

``fmu``: the example FMUs (pythonfmu: Python inside the FMU) against the built-in models. The vehicle
(``examples/fmu_vehicle``, RK4, one doStep per 10 ms dynamics step) on a 60 m arc with the cart 1.5 m behind and
0.8 m beside its setpoint at t = 0, ground truth, no renderer, 30 s: the vehicle part of a frame
(``model._advance_vehicles``) from the same states, FMU against the built-in exponential and RK4 methods; whole runs
in-process; the largest tractor and cart position difference from the FMU's run; the bare FMU call. The controller
(``examples/fmu_controller``) against the built-in ``section_fill`` with ``estimator: paper``: the whole 60 s run.
"""
from __future__ import annotations

import importlib.util
import math
import tempfile
import time
from pathlib import Path

from harness import Context, case, rotating

__all__ = ["api_overhead", "extreme", "fmu"]

#: the packaged scenarios of ``extreme``
EXTREMES = ("default", "stiff_drivetrain", "high_flow", "fast_harvest", "misaligned_start", "heavy_noise",
            "grazing_sensor", "near_alpha", "curved_pass", "soybeans", "back_to_front", "lowest_first")
#: the FMU vehicle's manoeuvre and the built-in models it is compared with
MANOEUVRE = ["combine.path=arc", "combine.path_radius_m=60.0", "machine_sync.initial_lat_error_m=0.8",
             "machine_sync.initial_long_error_m=-1.5"]
BUILTIN = {"exponential": ["vehicles.tractor_cart.fmu=null"],
           "rk4": ["vehicles.tractor_cart.fmu=null", "integrator.method=rk4"]}
POSITIONS = ("tractor_x_m", "tractor_y_m", "cart_x_m", "cart_y_m")


def _cm(v) -> float | None:
    """Metres as centimetres (None for a missing or NaN value)."""
    return None if v is None or (isinstance(v, float) and math.isnan(v)) else 100 * v


@case("extreme", "the stiff and extreme packaged scenarios run to the end with perception in the loop: their metrics",
      options={"scenarios": ",".join(EXTREMES), "estimator": "fused", "renderer": "gl", "duration": None},
      quick={"scenarios": "stiff_drivetrain", "renderer": "mock", "duration": 3.0}, settings=True)
def extreme(ctx: Context) -> dict:
    """Each scenario of ``scenarios`` in-process (module docstring); ``duration``: cut every run short (a check)."""
    from cosim.runtime.inprocess import simulate
    from cosim.runtime.outputs import compose_summary

    rows = {}
    for name in ctx["scenarios"].split(","):
        extra = {"renderer": ctx["renderer"], "controller": {"estimator": ctx["estimator"]}}
        if ctx["duration"]:
            extra["duration_s"] = ctx["duration"]
        sc = ctx.scenario(name, extra=extra)
        r = simulate(sc)
        s = compose_summary(sc, r.recorder, r.ring, wall_time_s=r.wall_time_s, error=None)
        f, p, c = s["fill"], s.get("perception") or {}, s.get("controller") or {}
        rows[name] = {"overfill cm": _cm(f["max_overfill_m"]), "profile RMSE cm": _cm(f["profile_rmse_m"]),
                      "spill kg": s["spill"]["mass_kg"], "time to target s": f.get("time_to_target_s"),
                      "nudges": c.get("nudges"), "% cart found": _cm(p.get("cart_found_fraction")),
                      "height RMSE cm": _cm(p.get("heightmap_rmse_m")), "% coverage": _cm(p.get("coverage")),
                      "sim s": s["sim_time_s"], "wall s": s["wall_time_s"]}
    return {f"{ctx['estimator']} estimator, renderer {ctx['renderer']}": rows}


@case("api_overhead", "the per-frame cost of driving a run through cosim.Simulation against simulate()",
      options={"duration": 60.0, "feedback": "ground_truth", "renderer": "none"}, quick={"duration": 2.0}, rounds=7,
      settings=True)
def api_overhead(ctx: Context) -> dict:
    """The three ways of running, rotating order (module docstring)."""
    from cosim import Simulation
    from cosim.runtime.inprocess import simulate

    s = ctx.scenario("default", extra={"feedback": ctx["feedback"], "renderer": ctx["renderer"],
                                        "duration_s": ctx["duration"]})
    frames = s.frames + 1

    def whole() -> float:
        t0 = time.perf_counter()
        simulate(s)
        return time.perf_counter() - t0

    def api(n: int) -> float:
        t0 = time.perf_counter()
        with Simulation(s) as sim:
            sim.reset()
            while not sim.done:
                sim.step(n)
        return time.perf_counter() - t0

    ways = {"simulate()": whole, "Simulation.step(1)": lambda: api(1), "Simulation.step(10)": lambda: api(10)}
    for fn in ways.values():                              # warm-up: imports, caches
        fn()
    ms = {k: ways[k]() / frames * 1e3 for k in rotating(list(ways), ctx.round)}
    base = ms["simulate()"]
    return {f"{frames} frames, {ctx['feedback']}, renderer {ctx['renderer']}": {
        k: {"ms per frame": ms[k], "over simulate() ms": ms[k] - base} for k in ways}}


def _build(tree: Path, dest: Path, example: str) -> Path:
    spec = importlib.util.spec_from_file_location(f"build_{example}", tree / "examples" / example / "build.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.build(dest)


@case("fmu", "cost and accuracy of the FMUs in the loop (vehicle, controller) against the built-in models",
      options={"duration": None}, quick={"duration": 2.0}, rounds=7)
def fmu(ctx: Context) -> dict:
    """The vehicle and controller comparisons of the module docstring; ``duration``: cut the runs short (a check)."""
    import numpy as np

    from cosim.runtime.inprocess import simulate
    from cosim.scenario.loader import load_scenario
    from dynamics_proc.fmu.models import open_fmus
    from dynamics_proc.model import ModelParams, _advance_vehicles, initial_world, step_frame

    short = [f"duration_s={ctx['duration']}"] if ctx["duration"] else []
    with tempfile.TemporaryDirectory(prefix="bench-fmu-") as tmp:
        tmp = Path(tmp)
        scen = tmp / "vehicle.yaml"
        scen.write_text((ctx.tree / "examples/fmu_vehicle/scenario.yaml").read_text())
        _build(ctx.tree, tmp, "fmu_vehicle")
        runs = {"fmu": load_scenario(scen, MANOEUVRE + short),
                **{k: load_scenario(scen, MANOEUVRE + v + short) for k, v in BUILTIN.items()}}
        p_exp = ModelParams.from_scenario(runs["exponential"])
        w, states = initial_world(runs["exponential"], p_exp), []
        for _ in range(runs["exponential"].frames):
            nxt = step_frame(w, None, p_exp)
            states.append((w.x, nxt.setpoint, w.frame + 1))
            w = nxt

        def per_step(p) -> float:
            t0 = time.perf_counter()
            for x, sp, frame in states:
                _advance_vehicles(x, sp, p, frame)
            return (time.perf_counter() - t0) / (len(states) * p.steps)

        step_us, bare_us = {}, None
        fmus = open_fmus(runs["fmu"])
        try:
            step_us["fmu"] = 1e6 * per_step(ModelParams.from_scenario(runs["fmu"], fmus))
            slave, n = fmus.vehicle.slave, 3000
            t0 = time.perf_counter()
            for i in range(n):
                slave.step([2.0, 0.01], 100.0 + i * 0.01, 0.01, 1)
            bare_us = 1e6 * (time.perf_counter() - t0) / n
        finally:
            fmus.close()
        for k in BUILTIN:
            step_us[k] = 1e6 * per_step(ModelParams.from_scenario(runs[k]))
        run_s, series = {}, {}
        for k in rotating(list(runs), ctx.round):
            t0 = time.perf_counter()
            r = simulate(runs[k])
            run_s[k] = time.perf_counter() - t0
            series[k] = r.recorder.series()
        vehicle = {}
        for k in runs:
            diff = None if k == "fmu" else max(float(np.max(np.abs(series["fmu"][f"dyn_state.{c}"]
                                                                   - series[k][f"dyn_state.{c}"]))) for c in POSITIONS)
            vehicle["FMU (pythonfmu, RK4)" if k == "fmu" else f"built-in {k}"] = {
                "per dynamics step us": step_us[k], "whole run in-process s": run_s[k],
                "max position difference from the FMU m": diff}
        vehicle["the bare FMU call (set 2 inputs, doStep, get 6 outputs)"] = {"per dynamics step us": bare_us}
        ctrl = tmp / "controller.yaml"
        ctrl.write_text((ctx.tree / "examples/fmu_controller/scenario.yaml").read_text())
        _build(ctx.tree, tmp, "fmu_controller")
        ctrl_runs = {"FMU": load_scenario(ctrl, short),
                     "built-in section_fill (paper)": load_scenario(ctrl, ["controller.model=section_fill",
                                                                          "controller.fmu=null",
                                                                          "controller.estimator=paper", *short])}
        controller = {}
        for k in rotating(list(ctrl_runs), ctx.round):
            t0 = time.perf_counter()
            simulate(ctrl_runs[k])
            controller[k] = {"whole run in-process s": time.perf_counter() - t0}
    return {"vehicle model": vehicle, "controller": {k: controller[k] for k in ctrl_runs}}
