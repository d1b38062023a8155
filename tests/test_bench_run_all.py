"""bench/run_all.py: the results' structure and Markdown from the harness's case results (fast), and its --quick mode
end to end (slow)."""
from __future__ import annotations

import importlib.util
import json
import math
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT / "bench") not in sys.path:
    sys.path.insert(0, str(ROOT / "bench"))


def _module():
    spec = importlib.util.spec_from_file_location("run_all", ROOT / "bench" / "run_all.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _e2e_sample(wall: float, cpu: float, ring: float, peaks, evaluation: str = "every 10 frames") -> dict:
    """One sample of the e2e case, as bench/cases/launched.py writes it."""
    return {"run": {"default": {"wall s": wall, "CPU s": cpu, "ring wall s": ring, "real-time factor (ring)": 120.0 / ring}},
            "LiDAR range error against the exact ray cast": {"mm": {
                "evaluation": evaluation, "frames evaluated": 12, "mean mm": 0.98, "median mm": 0.97, "p99 mm": 1.94,
                "max mm": 1.97, "p99 in 2-15 m mm": 1.94, "% above 5 cm in 2-15 m": 0.0}},
            "fill": {"default": {"lowest section peak m": min(peaks), "highest section peak m": max(peaks),
                                 "max overfill m": 0.009, "profile RMSE m": 0.007, "time to target s": 88.7,
                                 "spill kg": 0.0, "mass balance, relative error": 1e-14}}}


def test_figures_and_markdown_from_the_cases_results():
    """figures() takes medians over the e2e case's interleaved rounds, the ratios of the perception run's to the
    ground-truth run's wall and CPU times round by round, the fill and range figures of the first runs, and the
    beam_native and mock_cast cases' ratios; the Markdown carries every headline figure."""
    ra = _module()
    from harness import Arm, Result, get

    p = [_e2e_sample(30.0, 9.0, 12.0, [1.894, 1.909]), _e2e_sample(40.0, 12.0, 14.0, [1.8, 1.95]),
         _e2e_sample(35.0, 10.0, 13.0, [1.7, 1.96])]
    g = [_e2e_sample(10.0, 3.0, 2.0, [1.892, 1.903]), _e2e_sample(6.0, 3.0, 3.0, [1.8, 1.9]),
         _e2e_sample(8.0, 5.0, 4.0, [1.8, 1.9])]
    e2e = Result(get("e2e"), {"scenario": "default"}, list(ra.ARMS), 3, {"ground_truth": g, "perception": p})
    step = Result(get("beam_native"), {"frames": 4, "renderers": "gl"}, [Arm("this")], 1, {"this": [
        {"render + LiDAR step": {"gl camera_rig": {"CPU ms/frame": 8.0}, "gl beam_native": {"CPU ms/frame": 4.0}}}]})
    mock = Result(get("mock_cast"), {"frames": 2}, [Arm("this")], 1, {"this": [
        {"beam renderers, default scene": {"embree-static": {"CPU ms/frame": 5.0}, "gl": {"CPU ms/frame": 2.5}}}]})
    res = ra.figures(e2e, step, mock)
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
    assert res["perception"]["fill"]["section_peak_max_m"] == 1.909                    # the first round's run
    assert res["ground_truth"]["fill"]["section_peak_min_m"] == 1.892
    assert res["perception"]["range_error"]["median_m"] == pytest.approx(0.00097)
    assert res["lidar_step"]["ratio_cpu"] == 0.5 and res["mock_frame"]["ratio_cpu"] == 2.0
    res["meta"] = {"command": "python bench/run_all.py", "scenario": "default", "duration_s": 120.0, "rounds": 3,
                   "renderer": "gl", "written_utc": "2026-01-01T00:00:00+00:00", "cores": 2, "machine": "x86_64",
                   "python": "3.11", "load_average": [1.0, 1.2], "commit": "abc"}
    json.dumps(res, allow_nan=False)
    md = ra.render_markdown(res)
    for text in ("**4.38x** whole-process wall time", "3.00-6.67x; ratio of the medians 4.38x", "4.33x ring wall time",
                 "**3.00x** CPU time of the process tree", "wall at most 2.0x (NOT met)", "CPU at most 3.0x (met)",
                 "| highest section peak (m) | 1.909 | 1.903 |",
                 "median 0.97 mm", "p99 1.94 mm", "0.000 % of beams above 5 cm", "**0.50x**", "bench/HISTORY.md",
                 "5.00 against 2.50 ms CPU: **2.00x** (target: at most 1x"):
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
    assert res["curves"]["curves"]["median"]["CPU per frame against beams (ms)"]["100 x 100"]["beams"] == 10_000


def test_a_run_without_curves_keeps_the_last_curves_with_their_origin(tmp_path):
    ra = _module()
    results = tmp_path / "results.md"
    assert ra.kept_curves_section(results) == ""                       # nothing to keep
    results.write_text("# Current benchmark results\n\nWritten by `python bench/run_all.py ` at 2026-11-27T19:54:58"
                       "+00:00 from commit `0c06f38704`: 2 cores.\n\nheadline\n\n"
                       f"{ra.CURVES_HEADING} (cases `curves`)\n\n### beams\n\n| a | b |\n\n"
                       f"{ra.SUITE_HEADING}\n\nsuite table\n")
    kept = ra.kept_curves_section(results)
    assert kept.startswith(f"\n{ra.CURVES_HEADING} (cases `curves`)\n")
    assert "as written at 2026-11-27T19:54:58+00:00 from commit `0c06f38704`" in kept
    assert "### beams" in kept and ra.SUITE_HEADING not in kept               # up to the next section only
    assert ra.kept_suite_section(results).strip() == f"{ra.SUITE_HEADING}\n\nsuite table"
    # kept again by a later --no-curves run: the origin stays that of the run that measured them
    results.write_text("Written by `x` at 2026-11-28T00:00:00+00:00 from commit `abcdef1234`: 2 cores.\n" + kept)
    assert ra.kept_curves_section(results) == kept
