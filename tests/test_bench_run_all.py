"""bench/run_all.py: the results' structure and Markdown (fast), and its --quick mode end to end (slow)."""
from __future__ import annotations

import importlib.util
import json
import math
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _module():
    spec = importlib.util.spec_from_file_location("run_all", ROOT / "bench" / "run_all.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _summary(wall: float, rtf: float, peaks, evaluation: str = "every 10 frames, 4096 sampled beams each") -> dict:
    return {"wall_time_s": wall, "real_time_factor": rtf,
            "fill": {"section_peak_height_m": peaks, "max_overfill_m": 0.009, "profile_rmse_m": 0.007,
                     "time_to_target_s": 88.7},
            "spill": {"mass_kg": 0.0}, "mass_balance": {"relative_error": 1e-14},
            "perception": {"range_error": {"evaluation": evaluation, "frames_evaluated": 12, "mean_m": 0.00098,
                                           "median_m": 0.00097, "p99_m": 0.00194, "max_m": 0.00197,
                                           "working_frac_above_5cm": 0.0, "working_p99_m": 0.00194}}}


def test_figures_and_markdown_from_runs(monkeypatch):
    """measure() takes medians over interleaved runs, the ratios of the perception run's to the ground-truth
    run's wall times, the fill and range figures of the first runs; the Markdown carries every headline figure."""
    ra = _module()
    walls = {"perception": iter([(30.0, 12.0), (40.0, 14.0), (35.0, 13.0)]),
             "ground_truth": iter([(10.0, 2.0), (6.0, 3.0), (8.0, 4.0)])}
    cpus = {"perception": iter([9.0, 12.0, 10.0]), "ground_truth": iter([3.0, 3.0, 5.0])}
    order = []

    def fake_launch(scenario, duration, extra):
        lab = "ground_truth" if "ground_truth" in extra else "perception"
        order.append(lab)
        wall, ring = next(walls[lab])
        return {"wall_s": wall, "cpu_s": next(cpus[lab]),
                "summary": _summary(ring, duration / ring, [1.894, 1.909] if lab == "perception" else [1.892, 1.903])}

    monkeypatch.setattr(ra, "launch", fake_launch)
    monkeypatch.setattr(ra, "mock_ratio", lambda frames: {"frames": frames, "mock_cpu_ms": 5.0, "gl_cpu_ms": 2.5,
                                                          "ratio_cpu": 2.0})
    monkeypatch.setattr(ra, "step_ratio", lambda frames, renderer: {
        "renderer": renderer, "frames": frames, "camera_rig_cpu_ms": 8.0, "beam_native_cpu_ms": 4.0, "ratio_cpu": 0.5})
    res = ra.measure("default", 120.0, 3, 4, "gl")
    assert order == ["perception", "ground_truth", "ground_truth", "perception", "perception", "ground_truth"]
    assert res["perception"]["wall_s"] == 35.0 and res["ground_truth"]["wall_s"] == 8.0
    assert res["ratio"]["wall"] == pytest.approx(35.0 / 8.0)
    assert res["ratio"]["ring_wall"] == pytest.approx(13.0 / 3.0)
    # each round's own ratio (30/10, 40/6, 35/8): median 35/8, range 3.0 to 40/6
    assert res["ratio"]["wall_paired"] == pytest.approx({"median": 35.0 / 8.0, "min": 3.0, "max": 40.0 / 6.0})
    # CPU: 9/3, 12/3, 10/5 -> median 3.0 (the target, met), ratio of the medians 10/3
    assert res["ratio"]["cpu_paired"] == pytest.approx({"median": 3.0, "min": 2.0, "max": 4.0})
    assert res["ratio"]["cpu"] == pytest.approx(10.0 / 3.0)
    assert res["targets"] == {"wall": 2.0, "cpu": 3.0, "wall_met": False, "cpu_met": True}
    assert res["perception"]["real_time_factor"] == pytest.approx(120.0 / 13.0)
    assert res["perception"]["fill"]["section_peak_max_m"] == 1.909
    assert res["ground_truth"]["fill"]["section_peak_min_m"] == 1.892
    assert res["perception"]["range_error"]["median_m"] == 0.00097
    json.dumps(res, allow_nan=False)
    md = ra.render_markdown(res)
    for text in ("**4.38x** whole-process wall time", "3.00-6.67x; ratio of the medians 4.38x", "4.33x ring wall time",
                 "**3.00x** CPU time of the process tree", "wall at most 2.0x (NOT met)", "CPU at most 3.0x (met)",
                 "| highest section peak (m) | 1.909 | 1.903 |",
                 "median 0.97 mm", "p99 1.94 mm", "0.000 % of beams above 5 cm", "**0.50x**", "bench/HISTORY.md",
                 "5.00 against 2.50 ms CPU: **2.00x** (target: at most 1x)"):
        assert text in md


@pytest.mark.slow
def test_quick_mode_writes_both_files(tmp_path):
    """--quick with the mock renderer launches both runs and the step, and writes results.json / results.md with
    every figure finite (the quick numbers themselves are not headline figures)."""
    ra = _module()
    res = ra.main(["--quick", "--renderer", "mock", "--out", str(tmp_path)])
    on_disk = json.loads((tmp_path / "results.json").read_text())
    assert on_disk["ratio"].keys() == {"wall", "cpu", "ring_wall", "wall_paired", "cpu_paired"}
    for v in (res["ratio"]["wall"], res["ratio"]["cpu"], res["ratio"]["ring_wall"], res["lidar_step"]["ratio_cpu"],
              res["perception"]["real_time_factor"], res["ground_truth"]["real_time_factor"]):
        assert math.isfinite(v) and v > 0
    assert res["perception"]["range_error"]["frames_evaluated"] >= 1
    md = (tmp_path / "results.md").read_text()
    assert "Quick mode" in md and "CPU per frame against beams" in md and "runs per hour" in md
    assert res["curves"]["beams"]["points"][0]["beams"] == 10_000
