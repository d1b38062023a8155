"""Cost and accuracy of the FMUs in the loop against the built-in models (docs/fmu.md): the vehicle, and the
controller.

The FMU is the example's (examples/fmu_vehicle/TractorCart.py, built with pythonfmu: Python inside the FMU, RK4,
one doStep per 10 ms dynamics step). Scenario: the example scenario on a 60 m arc with the cart 1.5 m behind and
0.8 m beside its setpoint at t = 0, ground-truth feedback, no renderer, 30 s (300 frames, 3000 dynamics steps).

1. Per dynamics step: the vehicle part of a frame (``model._advance_vehicles``: Machine Sync command + one
   integration step, x10) from the same states, FMU against the built-in exponential (default) and RK4 methods;
   interleaved A/B/C rounds, each round timing every frame of the run's state trajectory; medians over rounds.
2. Whole run in-process (``cosim.runtime.inprocess.simulate``): wall time, interleaved, medians.
3. Trajectory error: largest difference of tractor and cart positions (m) over the run, FMU against each built-in.
4. The bare FMU call (inputs set, doStep, outputs read) per step, for the share of the interface.
5. The controller FMU (examples/fmu_controller/SectionFill.py, pythonfmu) against the built-in ``section_fill``
   with ``estimator: paper`` (the same decisions): whole 60 s example run in-process, interleaved, medians.

Run: ``python bench/fmu.py [--rounds 7]`` (prints Markdown).
"""
from __future__ import annotations

import argparse
import importlib.util
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cosim.runtime.inprocess import simulate  # noqa: E402
from cosim.scenario.loader import load_scenario  # noqa: E402
from dynamics_proc.fmus import open_fmus  # noqa: E402
from dynamics_proc.model import ModelParams, _advance_vehicles, initial_world, step_frame  # noqa: E402

MANOEUVRE = ["combine.path=arc", "combine.path_radius_m=60.0", "machine_sync.initial_lat_error_m=0.8",
             "machine_sync.initial_long_error_m=-1.5"]
BUILTIN = {"exponential": ["vehicles.tractor_cart.fmu=null"],
           "rk4": ["vehicles.tractor_cart.fmu=null", "integrator.method=rk4"]}
COLUMNS = ("tractor_x_m", "tractor_y_m", "cart_x_m", "cart_y_m")


def _build(dest: Path, example: str = "fmu_vehicle") -> Path:
    spec = importlib.util.spec_from_file_location(f"build_{example}", ROOT / f"examples/{example}/build.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.build(dest)


def _trajectory(s, p) -> list:
    """(state, setpoint, frame) at the start of every frame of a built-in run."""
    w, out = initial_world(s, p), []
    for _ in range(s.frames):
        nxt = step_frame(w, None, p)
        out.append((w.x, nxt.setpoint, w.frame + 1))
        w = nxt
    return out


def _time_steps(p, states) -> float:
    """Seconds per dynamics step of the vehicle part over ``states``."""
    t0 = time.perf_counter()
    for x, sp, frame in states:
        _advance_vehicles(x, sp, p, frame)
    return (time.perf_counter() - t0) / (len(states) * p.steps)


def _time_slave(fmus, n: int = 3000) -> float:
    """Seconds per bare FMU step (set 2 inputs, doStep, get 6 outputs) at a fixed held command."""
    slave = fmus.vehicle.slave
    t0 = time.perf_counter()
    for i in range(n):
        slave.step([2.0, 0.01], 100.0 + i * 0.01, 0.01, 1)
    return (time.perf_counter() - t0) / n


def _controller_runs(tmp: Path, rounds: int) -> dict[str, list[float]]:
    """Wall times of the controller example run, FMU and built-in, interleaved."""
    scen = tmp / "controller.yaml"
    scen.write_text((ROOT / "examples/fmu_controller/scenario.yaml").read_text())
    _build(tmp, "fmu_controller")
    runs = {"fmu": load_scenario(scen), "builtin": load_scenario(scen, ["controller.model=section_fill",
                                                                      "controller.fmu=null", "controller.estimator=paper"])}
    out: dict[str, list[float]] = {k: [] for k in runs}
    for _ in range(rounds):
        for k, s in runs.items():
            t0 = time.perf_counter()
            simulate(s)
            out[k].append(time.perf_counter() - t0)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=7)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        scen = Path(tmp) / "scenario.yaml"
        scen.write_text((ROOT / "examples/fmu_vehicle/scenario.yaml").read_text())
        _build(Path(tmp))
        s_fmu = load_scenario(scen, MANOEUVRE)
        s_in = {k: load_scenario(scen, MANOEUVRE + v) for k, v in BUILTIN.items()}
        p_in = {k: ModelParams.from_scenario(s) for k, s in s_in.items()}
        states = _trajectory(s_in["exponential"], p_in["exponential"])
        step_us = {k: [] for k in ("fmu", *BUILTIN)}
        bare_us = []
        run_s = {k: [] for k in ("fmu", *BUILTIN)}
        for _ in range(args.rounds):
            fmus = open_fmus(s_fmu)
            try:
                step_us["fmu"].append(1e6 * _time_steps(ModelParams.from_scenario(s_fmu, fmus), states))
                bare_us.append(1e6 * _time_slave(fmus))
            finally:
                fmus.close()
            for k, p in p_in.items():
                step_us[k].append(1e6 * _time_steps(p, states))
            for k, s in (("fmu", s_fmu), *s_in.items()):
                t0 = time.perf_counter()
                simulate(s)
                run_s[k].append(time.perf_counter() - t0)
        series = {k: simulate(s).recorder.series() for k, s in (("fmu", s_fmu), *s_in.items())}
        ctrl_s = _controller_runs(Path(tmp), args.rounds)
    print(f"| vehicle model | per dynamics step (us, median of {args.rounds}) | whole 30 s run in-process (s) | "
          "max position difference from the FMU (m) |")
    print("|---|---|---|---|")
    for k in ("fmu", *BUILTIN):
        err = "-" if k == "fmu" else "%.1e" % max(
            float(np.max(np.abs(series["fmu"][f"dyn_state.{c}"] - series[k][f"dyn_state.{c}"]))) for c in COLUMNS)
        name = "FMU (pythonfmu, RK4)" if k == "fmu" else f"built-in {k}"
        print(f"| {name} | {statistics.median(step_us[k]):.1f} | {statistics.median(run_s[k]):.2f} | {err} |")
    print(f"\nof which the FMU call alone (set 2 inputs, doStep, get 6 outputs): {statistics.median(bare_us):.1f} us")
    print(f"\ncontroller, whole 60 s run in-process (s, median of {args.rounds}): FMU "
          f"{statistics.median(ctrl_s['fmu']):.2f}, built-in section_fill (paper) {statistics.median(ctrl_s['builtin']):.2f}")


if __name__ == "__main__":
    main()
