"""The stiff and extreme packaged scenarios with perception in the loop (GL renderer, in process).

The fast check (CI): the first 8 s of each, long enough for the cart to be found, the first measurement to
reach the controller and the auger to start: finite numbers, exact mass balance, no spill, the cart found in
most frames. The whole runs, with their metrics, are a slow study (``pytest -m slow``) and a benchmark
(``python bench/run.py extreme``).
"""
from __future__ import annotations

import numpy as np
import pytest

from cosim.errors import RendererUnavailable
from cosim.runtime.inprocess import simulate
from cosim.runtime.outputs import compose_summary
from cosim.scenario.loader import load_scenario, packaged_scenarios

pytestmark = pytest.mark.gl

EXTREME = ["stiff_drivetrain", "high_flow", "fast_harvest", "misaligned_start", "heavy_noise", "grazing_sensor",
           "near_alpha"]


def run(name: str, duration: float | None):
    extra = {"renderer": "gl"} if duration is None else {"renderer": "gl", "duration_s": duration}
    sc = load_scenario(packaged_scenarios()[name], extra=extra)
    assert sc.feedback == "perception"
    try:
        r = simulate(sc)
    except RendererUnavailable as exc:
        pytest.skip(str(exc))
    summary = compose_summary(sc, r.recorder, r.ring, wall_time_s=r.wall_time_s, error=None)
    return sc, r.recorder.series(), summary


def check(series: dict, summary: dict) -> None:
    for col, values in series.items():
        assert np.all(np.isfinite(values) | col.endswith(("_fullness", "_sigma_m")) | col.startswith("perc_state.")), col
    mb = summary["mass_balance"]
    assert abs(mb["delivered_m3"] - mb["in_cart_m3"] - mb["spilled_m3"]) <= 1e-9 * max(mb["delivered_m3"], 1.0)
    assert summary["spill"]["mass_kg"] == pytest.approx(0.0, abs=1e-9)


@pytest.mark.parametrize("name", EXTREME)
def test_first_seconds_with_perception(name):
    sc, series, summary = run(name, 8.0)
    check(series, summary)
    if name == "grazing_sensor":
        # the mast sees the cart only at grazing angles: perception must say it has no answer, and the
        # controller must then never start the auger blind
        assert series["perc_state.cart_valid"].max() == 0
        assert summary["mass_balance"]["delivered_m3"] == 0.0 and series["dyn_state.auger_on"].max() == 0
        return
    assert series["dyn_state.measurement_seen"][-1] == 1, "no perceived map ever reached the controller"
    assert summary["mass_balance"]["delivered_m3"] > 0.05, "the auger never started"
    found = series["perc_state.cart_valid"][1:]
    assert found.mean() >= 0.8, f"cart found in only {found.mean():.0%} of frames"


@pytest.mark.slow
@pytest.mark.parametrize("name", EXTREME)
def test_whole_run_with_perception(name):
    """To the end: finished, no spill, within 5 cm of the target everywhere (high_flow, whose 5x flow lands
    ~15 cm of transit grain even with ideal feedback, within 20 cm)."""
    sc, series, summary = run(name, None)
    check(series, summary)
    if name == "grazing_sensor":
        assert summary["mass_balance"]["delivered_m3"] == 0.0
        return
    assert series["dyn_state.all_full"][-1] == 1
    over = summary["fill"]["max_overfill_m"]
    assert over <= (0.20 if name == "high_flow" else 0.05), over


def test_heavy_noise_near_the_rim_keeps_the_cart_in_place():
    """heavy_noise's 5 cm range noise with the grain filled near the rim from the start: the rim band may not
    take in the grain surface (a 3-sigma band did: a partly seen cart moved by 0.45 m in one frame of ten).
    Measured: 90th percentile of the cart x error 0.07 m with the 1-sigma band, 0.45 m with 3 sigma."""
    sc = load_scenario(packaged_scenarios()["heavy_noise"],
                       extra={"renderer": "gl", "duration_s": 6.0, "grain": {"initial_fill_m": 1.8},
                              "sensor": {"noise": {"dropout": 0.0}}})
    try:
        s = simulate(sc).recorder.series()
    except RendererUnavailable as exc:
        pytest.skip(str(exc))
    valid = s["perc_state.cart_valid"] == 1
    assert valid.mean() > 0.6
    err = np.abs(s["perc_state.cart_x_m"] - s["dyn_state.cart_x_m"])[valid]
    assert np.percentile(err, 90) < 0.15, np.percentile(err, 90)
