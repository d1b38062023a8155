"""summary.json parts from a hand-built series and height map (values known in closed form)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from cosim.scenario.config import Scenario
from dynamics_proc.summary import summarize


def test_summary_from_hand_built_series():
    s = Scenario.model_validate({"format_version": 1, "feedback": "ground_truth", "renderer": "none"})
    h = np.full((60, 30), 1.5)
    h[:7, :] = 1.95                                          # section 1 (rows 0..6) at 1.95
    h[7, 3] = 2.0                                            # one cell of section 2 at 2.0
    series = {
        "dyn_state.t_s": np.array([0.0, 0.1, 0.2, 0.3]),
        "dyn_state.all_full": np.array([0.0, 0.0, 1.0, 1.0]),
        "dyn_state.delivered_m3": np.array([0.0, 1.0, 2.0, 3.0]),
        "dyn_state.in_cart_m3": np.array([0.0, 1.0, 2.0, 2.5]),
        "dyn_state.spilled_m3": np.array([0.0, 0.0, 0.0, 0.5]),
        "dyn_state.nudge_count": np.array([0.0, 1.0, 2.0, 4.0]),
        "dyn_state.auger_on": np.array([0.0, 1.0, 0.0, 1.0]),
    }
    sm = summarize(s, series, h.astype(np.float32))
    f = sm["fill"]
    assert f["target_height_m"] == 1.9
    assert f["section_peak_height_m"][:2] == pytest.approx([1.95, 2.0])
    assert f["section_peak_height_m"][2:] == pytest.approx([1.5] * 7)
    assert f["section_mean_height_m"][1] == pytest.approx((1.5 * 6 * 30 - 1.5 + 2.0) / (6 * 30))
    assert f["max_overfill_m"] == pytest.approx(0.1)
    peaks = np.array([1.95, 2.0] + [1.5] * 7)
    assert f["profile_rmse_m"] == pytest.approx(math.sqrt(np.mean((peaks - 1.9) ** 2)), rel=1e-6)
    assert f["fill_fraction"] == pytest.approx((7 * 30 * 1.95 + 53 * 30 * 1.5 + 0.5) * 0.01 / 36.0, rel=1e-7)
    assert f["time_to_target_s"] == pytest.approx(0.2)
    assert sm["spill"] == {"mass_kg": pytest.approx(0.5 * 720.0), "volume_m3": 0.5}
    assert sm["mass_balance"]["relative_error"] == 0.0
    assert sm["controller"]["nudges"] == 4 and sm["controller"]["auger_starts"] == 2


def test_summary_of_an_empty_run_is_nan_not_an_error():
    s = Scenario.model_validate({"format_version": 1, "feedback": "ground_truth", "renderer": "none"})
    sm = summarize(s, {}, None)
    assert math.isnan(sm["fill"]["time_to_target_s"]) and math.isnan(sm["mass_balance"]["delivered_m3"])
    assert sm["controller"]["nudges"] == 0 and len(sm["fill"]["section_peak_height_m"]) == 9
