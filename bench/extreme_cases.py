"""Stiff and extreme packaged scenarios run to the end with perception in the loop: their metrics.

Each scenario runs whole, in process, with the GL renderer and its packaged settings (fused estimator unless
``--estimator paper``); prints a Markdown table: fill (max overfill above target, profile RMSE, spill), time
to target, nudges, perception (cart found, height-map RMSE and coverage) and wall time. Metrics do not depend
on the machine's load (the loop is deterministic); wall times do. Usage:
``python bench/extreme_cases.py [--estimator paper] [--only NAME]``.
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from cosim.runtime.inprocess import simulate  # noqa: E402
from cosim.runtime.outputs import compose_summary  # noqa: E402
from cosim.scenario.loader import load_scenario, packaged_scenarios  # noqa: E402

CASES = ["default", "stiff_drivetrain", "high_flow", "fast_harvest", "misaligned_start", "heavy_noise",
         "grazing_sensor", "near_alpha", "curved_pass", "soybeans", "back_to_front", "lowest_first"]


def cm(v) -> str:
    return "-" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{v * 100:.1f}"


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--estimator", default="fused", choices=["fused", "paper"])
    ap.add_argument("--only", default="", help="comma-separated scenario names (default: all)")
    ap.add_argument("--renderer", default="gl", choices=["gl", "mock"])
    args = ap.parse_args(argv)
    names = [n for n in CASES if not args.only or n in args.only.split(",")]
    print("| scenario | overfill (cm) | profile RMSE (cm) | spill (kg) | time to target (s) | nudges | cart found | "
          "height RMSE (cm) | coverage | sim s | wall s |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for name in names:
        sc = load_scenario(packaged_scenarios()[name], extra={"renderer": args.renderer,
                                                               "controller": {"estimator": args.estimator}})
        r = simulate(sc)
        s = compose_summary(sc, r.recorder, r.ring, wall_time_s=r.wall_time_s, error=None)
        f, p, c = s["fill"], s.get("perception") or {}, s.get("controller") or {}
        ttt = f.get("time_to_target_s")
        print(f"| {name} | {cm(f['max_overfill_m'])} | {cm(f['profile_rmse_m'])} | {s['spill']['mass_kg']:.1f} | "
              f"{'-' if ttt is None or math.isnan(ttt) else f'{ttt:.1f}'} | {c.get('nudges', '-')} | "
              f"{p.get('cart_found_fraction', math.nan):.0%} | {cm(p.get('heightmap_rmse_m'))} | "
              f"{p.get('coverage', math.nan):.0%} | {s['sim_time_s']:.0f} | {s['wall_time_s']:.0f} |", flush=True)


if __name__ == "__main__":
    main()
