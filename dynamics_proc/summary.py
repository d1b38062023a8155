"""summary.json parts owned by dynamics: ``fill``, ``spill``, ``mass_balance``, ``controller`` (docs/architecture.md).

Computed in the launcher process from the recorded series and the final truth height map alone.
"""
from __future__ import annotations

import math

import numpy as np

from cosim.scenario.config import Scenario
from dynamics_proc.grain.fill import section_rows

__all__ = ["summarize", "section_stats"]


def _last(series: dict[str, np.ndarray], field: str) -> float:
    a = series.get(f"dyn_state.{field}")
    return float(a[-1]) if a is not None and len(a) else math.nan


def section_stats(h: np.ndarray, scenario: Scenario) -> tuple[np.ndarray, np.ndarray]:
    """(peak (N,), mean (N,)) grain height m per section of the truth map ``h`` (nx, ny) m."""
    h = np.asarray(h, dtype=np.float64)
    n = scenario.controller.sections
    rows = section_rows(h.shape[0], scenario.grain.cell_m, scenario.cart.interior_length_m, n)
    peak = np.array([h[rows == k].max() if np.any(rows == k) else math.nan for k in range(n)])
    mean = np.array([h[rows == k].mean() if np.any(rows == k) else math.nan for k in range(n)])
    return peak, mean


def summarize(scenario: Scenario, series: dict[str, np.ndarray], heightmap_truth: np.ndarray | None) -> dict:
    """The dynamics parts of summary.json. ``series``: ``"dyn_state.<field>"`` -> (frames,) float64;
    ``heightmap_truth``: final (nx, ny) m or None. Unknown values are NaN (written as null)."""
    target = scenario.controller.target_fill_m
    n = scenario.controller.sections
    cart = scenario.cart
    if heightmap_truth is not None:
        h = np.asarray(heightmap_truth, dtype=np.float64)
        peak, mean = section_stats(h, scenario)
        overfill = max(0.0, float(h.max()) - target)
        rmse = float(np.sqrt(np.mean((peak - target) ** 2)))
        fraction = float(h.sum()) * scenario.grain.cell_m ** 2 / cart.volume_m3
    else:
        peak = mean = np.full(n, math.nan)
        overfill = rmse = fraction = math.nan
    t = series.get("dyn_state.t_s", np.empty(0))
    full = series.get("dyn_state.all_full", np.empty(0))
    hit = np.flatnonzero(full > 0.5)
    time_to_target = float(t[hit[0]]) if hit.size else math.nan
    delivered, in_cart, spilled = _last(series, "delivered_m3"), _last(series, "in_cart_m3"), _last(series,
                                                                                                    "spilled_m3")
    if delivered > 0.0:
        rel = abs(delivered - in_cart - spilled) / delivered
    else:
        rel = abs(in_cart + spilled) if math.isfinite(in_cart + spilled) else math.nan
    on = series.get("dyn_state.auger_on", np.empty(0))
    switches = int(np.count_nonzero(np.diff(on) > 0.5)) if on.size > 1 else 0
    dt = scenario.timing.sensor_period_s
    return {
        "fill": {
            "target_height_m": target,
            "section_peak_height_m": peak.tolist(),
            "section_mean_height_m": mean.tolist(),
            "max_overfill_m": overfill,
            "profile_rmse_m": rmse,
            "fill_fraction": fraction,
            "time_to_target_s": time_to_target,
        },
        "spill": {"mass_kg": spilled * scenario.crop.density, "volume_m3": spilled},
        "mass_balance": {"delivered_m3": delivered, "in_cart_m3": in_cart, "spilled_m3": spilled,
                         "relative_error": rel},
        "controller": {
            "nudges": int(_last(series, "nudge_count")) if math.isfinite(_last(series, "nudge_count")) else 0,
            "strategy": scenario.controller.strategy,
            "auger_starts": switches,
            "auger_on_s": float(np.sum(on > 0.5)) * dt if on.size else 0.0,
            "latency_frames": scenario.timing.latency_frames,
        },
    }
