"""Fill strategies compared on the default cart (half full to 1.9 m), ground truth and a perceived stand-in.

"perceived" passes the truth (controller grid) through 30 % random holes and 2 cm Gaussian noise, a stand-in
for the perception process (seeded). Columns from summary.json's fill / spill / controller parts; "levelness at
50 %" is the spread (max - min) of the section mean heights when half of the run's grain has been delivered,
a measure of how even the load is if the operator stops early.

Run: ``python bench/dynamics_strategies.py`` (prints a Markdown table).
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from cosim.scenario.config import Scenario  # noqa: E402
from dynamics_proc.closed_loop import noisy_measurement, simulate  # noqa: E402
from dynamics_proc.summary import section_stats, summarize  # noqa: E402

HOLES = 0.3
SIGMA_M = 0.02


def levelness_at_half(s: Scenario, strategy_run) -> float:
    """Spread of section means (m) when half the grain is in: re-run to that frame and read the map."""
    d = strategy_run.series["dyn_state.delivered_m3"]
    half = int(np.searchsorted(d, 0.5 * d[-1]))
    r = simulate(s, half)
    _, mean = section_stats(r.heights, s)
    return float(mean.max() - mean.min())


def main() -> None:
    print("| feedback | strategy | time to target (s) | peak error max (cm) | profile rmse (cm) | fill fraction "
          "| spill (kg) | nudges | levelness at 50 % (cm) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for feedback in ("truth", "perceived"):
        for strategy in ("front_to_back", "back_to_front", "lowest_first"):
            s = Scenario.model_validate({"format_version": 1, "feedback": "ground_truth", "renderer": "none",
                                         "duration_s": 300.0, "controller": {"strategy": strategy}})
            measure = noisy_measurement(7, HOLES, SIGMA_M) if feedback == "perceived" else None
            r = simulate(s, stop_when_done=True, measure=measure)
            sm = summarize(s, r.series, r.heights)
            f = sm["fill"]
            err = np.max(np.abs(np.array(f["section_peak_height_m"]) - f["target_height_m"]))
            lev = levelness_at_half(s, r) if feedback == "truth" else float("nan")
            print(f"| {feedback} | {strategy} | {f['time_to_target_s']:.1f} | {err * 100:.1f} | "
                  f"{f['profile_rmse_m'] * 100:.1f} | {f['fill_fraction']:.3f} | {sm['spill']['mass_kg']:.1f} | "
                  f"{sm['controller']['nudges']} | {lev * 100:.1f} |")


if __name__ == "__main__":
    main()
