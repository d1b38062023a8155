"""The field-conditions suite: its packaged scenarios, the sweep file over all of them (a list of bases), and
bench/field_suite.py's table."""
from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

from cosim.scenario.loader import load_scenario, packaged_scenarios
from cosim.studies.sweepfile import load_sweep

ROOT = Path(__file__).resolve().parent.parent
CASES = ("rough_terrain", "side_slope", "gnss_noise", "stop_and_go", "headland_turn", "dusty", "dense_dust",
         "high_flow", "grazing_sensor", "blinding_dust")


def _bench(name: str):
    spec = importlib.util.spec_from_file_location(name, ROOT / "bench" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_the_suite_sweeps_every_case_over_a_hundred_new_seeds_with_perception():
    sweep = load_sweep(ROOT / "bench" / "field_suite.yaml")
    assert sweep.labels == ("base",) and len(sweep.runs) == len(CASES) * 100
    assert [r.labels["base"] for r in sweep.runs[::100]] == list(CASES)
    for run in sweep.runs[::100]:
        case = load_scenario(packaged_scenarios()[run.labels["base"]], ["sensor.noise.range_sigma_m=0.01"],
                             extra={"renderer": "mock", "seed": run.seed})
        assert run.scenario.feedback == "perception" and run.scenario.renderer == "mock"
        assert run.scenario.model_copy(update={"outputs": case.outputs, "plugin_dir": case.plugin_dir}) == case
        assert case.field.draw                                             # every case draws its field
    seeds = sorted({r.seed for r in sweep.runs})
    assert seeds == list(range(1000, 1100)) and len({r.id for r in sweep.runs}) == len(CASES) * 100
    fs = _bench("field_suite")
    assert set(fs.STOP_SAFE) == {"grazing_sensor", "blinding_dust"}
    order = fs.seed_major(sweep.runs, 2)                                   # what --run --seeds 2 submits
    assert [(r.seed, r.labels["base"]) for r in order] == [(s, c) for s in (1000, 1001) for c in CASES]


def test_the_wilson_interval_matches_its_closed_form():
    fs = _bench("field_suite")
    lo, hi = fs.wilson(98, 100)
    assert (round(lo, 4), round(hi, 4)) == (0.9300, 0.9945)               # the acceptance's margin: 98 of 100
    assert fs.wilson(95, 100)[0] < fs.FILLED_LOWER <= fs.wilson(98, 100)[0]
    assert fs.wilson(100, 100)[1] == 1.0 and fs.wilson(0, 20)[0] == 0.0
    for k, n in ((3, 10), (50, 100), (99, 100)):                           # centre and width of the score interval
        lo, hi = fs.wilson(k, n)
        z, p = fs.Z95, k / n
        assert 0.5 * (lo + hi) == pytest.approx((p + z * z / (2 * n)) / (1 + z * z / n), rel=1e-12)
        assert lo < p < hi


def _row(case, seed, outcome, overfill=0.01, reason="", ttt="90"):
    return {"base": case, "seed": seed, "outcome": outcome, "spill_kg": "0", "max_overfill_m": str(overfill),
            "time_to_target_s": ttt if outcome == "filled" else "", "outcome_reason": reason}


def test_the_table_judges_each_case_by_its_rule_and_names_the_seeds_of_each_failure(tmp_path):
    fs = _bench("field_suite")
    rows = ([_row("a", 1000 + i, "filled", 0.01 + 0.001 * i) for i in range(98)]
            + [_row("a", 1098, "stopped_safe", 0.0, "perception never found the cart: 0 of 1201 frames; ...")]
            + [_row("a", 1099, "stopped_safe", 0.0, "perception never found the cart: 0 of 601 frames")]
            + [_row("b", 1000 + i, "filled") for i in range(19)] + [_row("b", 1019, "job_failed", 0.07,
                                                                        "overfill 7 cm in section 9")]
            + [_row("grazing_sensor", 1000 + i, "stopped_safe", 0.0, "no usable height map yet") for i in range(5)]
            + [_row("blinding_dust", 1000, "stopped_safe", 0.0, "x"), _row("blinding_dust", 1001, "job_failed",
                                                                           0.0, "not filled when the run ended")])
    table = fs.summarize_results(rows)
    a, b = table["a"], table["b"]
    assert a["rule"] == "fill" and a["meets"] and a["filled_ci95"][0] == pytest.approx(0.93, abs=5e-4)
    assert a["reasons"] == {"stopped_safe: perception never found the cart: # of # frames": {
        "count": 2, "seeds": [1098, 1099]}}
    assert a["overfill_max_m"] == pytest.approx(0.107) and a["overfill_median_m"] == pytest.approx(0.0575)
    assert not b["meets"] and b["failures"] == {"job_failed: overfill # cm in section #": {"count": 1,
                                                                                         "seeds": [1019]}}
    assert table["grazing_sensor"]["rule"] == "stop-safe" and table["grazing_sensor"]["meets"]
    assert not table["blinding_dust"]["meets"]
    assert list(table["blinding_dust"]["failures"]) == ["job_failed: not filled when the run ended"]
    md = fs.render_markdown(table, {"runs": len(rows), "results": "runs/x", "written": "now"})
    assert "| `a` | fill | 100 | 98 % (93-99) | 2 % (1-7) | 0 % (0-4) | 0 % (0-4) | 5.8 / 10.2 / 10.7 | 0 | 90 | - | yes |" in md
    assert "* `b` (breaks its rule): 1x job_failed: overfill # cm in section #; seeds 1019" in md
    assert "* `a`: 2x stopped_safe: perception never found the cart: # of # frames; seeds 1098, 1099" in md
    results = tmp_path / "results.md"
    results.write_text("# Current benchmark results\n\nheadline\n\n## Field-conditions suite\n\nold\n\n## Later\n\nkept\n")
    fs.put_section(results, md)
    fs.put_section(results, md)                                      # replaced, not appended twice
    text = results.read_text()
    assert text.count(fs.SECTION) == 1 and "old" not in text and text.rstrip().endswith("## Later\n\nkept")
    assert _bench("run_all").kept_suite_section(results).strip().startswith(fs.SECTION)


def test_a_run_stopped_from_outside_is_no_outcome_but_a_run_that_failed_is():
    fs = _bench("field_suite")
    stopped = {"completed": False, "outcome": {"status": "job_failed", "reason": "the run did not complete "
                                                "(interrupted after 40.1 s): stopped by SIGINT at frame 401"}}
    crashed = {"completed": False, "outcome": {"status": "job_failed", "reason": "the run did not complete: "
                                                "perception crashed at frame 12"}}
    assert fs.interrupted(stopped) and not fs.interrupted(crashed)
    assert not fs.interrupted({**stopped, "completed": True})


def test_the_gl_comparison_counts_agreeing_outcomes_per_case():
    fs = _bench("field_suite")
    mock = [_row("a", 1000, "filled"), _row("a", 1001, "filled"), _row("b", 1000, "stopped_safe")]
    gl = [_row("a", 1000, "filled"), _row("a", 1001, "job_failed"), _row("b", 1000, "stopped_safe"),
          _row("b", 1005, "filled")]                                       # no mock run of that seed: not compared
    assert fs.compare_outcomes(mock, gl) == {
        "a": {"seeds": 2, "agree": 1, "differ": [{"seed": 1001, "mock": "filled", "gl": "job_failed"}]},
        "b": {"seeds": 1, "agree": 1, "differ": []}}
