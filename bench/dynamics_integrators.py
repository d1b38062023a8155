"""Error against run time of each integration method on the vehicle model (Machine Sync closed loop).

The controller is sampled once per 0.1 s frame (zero-order hold) and every method integrates the same
held-input problem over the frame: RK4 and the exponential method with 1..50 substeps, solve_ivp Radau / BDF
at several tolerances. Reference: Radau at rtol 1e-12. Scenario: arc path (R = 60 m), initial offsets of
1 m / -0.5 m and a +0.3 m nudge every 4 s, 20 s simulated; default drivetrain (tau 0.5 s) and stiff (1 ms).
Error: largest cart position deviation from the reference over the run (m). Cost: wall time per simulated s.

Run: ``python bench/dynamics_integrators.py`` (prints a Markdown table).
"""
from __future__ import annotations

import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from cosim.scenario.config import Scenario  # noqa: E402
from dynamics_proc.integrators import integrate  # noqa: E402
from dynamics_proc.machine_sync import SyncGains, sync_command  # noqa: E402
from dynamics_proc.vehicles import VehicleParams, cart_pose, initial_state  # noqa: E402

FRAME_S = 0.1
SIM_S = 20.0
NUDGE_EVERY_S = 4.0
NUDGE_M = 0.3


def scenario(tau_s: float) -> Scenario:
    return Scenario.model_validate({
        "format_version": 1, "feedback": "ground_truth", "renderer": "none",
        "combine": {"path": "arc", "path_radius_m": 60.0},
        "tractor": {"drivetrain_tau_s": tau_s},
        "machine_sync": {"initial_long_error_m": 1.0, "initial_lat_error_m": -0.5},
    })


def run(s: Scenario, method: str, substeps: int = 1, rtol: float = 1e-8, atol: float = 1e-10) -> tuple[np.ndarray,
                                                                                                           float]:
    """Cart positions (frames + 1, 2) m and wall time s."""
    p, g = VehicleParams.from_scenario(s), SyncGains.from_scenario(s)
    x = initial_state(s, p)
    sp = [s.machine_sync.longitudinal_offset_m, s.machine_sync.lateral_offset_m]
    frames = round(SIM_S / FRAME_S)
    out = np.empty((frames + 1, 2))
    out[0] = cart_pose(x, p)[:2]
    t0 = time.perf_counter()
    for m in range(1, frames + 1):
        if (m - 1) % round(NUDGE_EVERY_S / FRAME_S) == 0 and m > 1:
            sp[0] += NUDGE_M
        x = integrate(method, x, sync_command(x, tuple(sp), p, g), p, FRAME_S, substeps, rtol, atol)
        out[m] = cart_pose(x, p)[:2]
    return out, time.perf_counter() - t0


def main() -> None:
    rows = []
    for tau in (0.5, 0.001):
        s = scenario(tau)
        ref, _ = run(s, "radau", rtol=1e-12, atol=1e-12)
        cases = [("rk4", n, None) for n in (1, 2, 5, 10, 50)] + [("exponential", n, None) for n in (1, 2, 5, 10, 50)]
        cases += [(m, 1, r) for m in ("radau", "bdf") for r in (1e-3, 1e-6, 1e-9)]
        for method, n, rtol in cases:
            kw = {"rtol": rtol, "atol": rtol * 1e-2} if rtol else {}
            pos, wall = run(s, method, n, **kw)
            err = float(np.max(np.hypot(*(pos - ref).T))) if np.all(np.isfinite(pos)) else math.inf
            step = f"{FRAME_S / n * 1e3:g} ms" if rtol is None else f"rtol {rtol:g}"
            rows.append((tau, method, step, err, wall / SIM_S * 1e3))
    print("| drivetrain tau | method | step / tolerance | max cart position error (m) | wall ms per simulated s |")
    print("|---|---|---|---|---|")
    for tau, method, step, err, ms in rows:
        print(f"| {tau:g} s | {method} | {step} | {err:.2e} | {ms:.2f} |")


if __name__ == "__main__":
    main()
