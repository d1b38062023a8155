"""The field-conditions suite: its packaged scenarios, the sweep file over all of them (a list of bases), and
bench/field_suite.py's table."""
from __future__ import annotations

import importlib.util
from pathlib import Path

from cosim.scenario.loader import load_scenario, packaged_scenarios
from cosim.studies.sweepfile import load_sweep

ROOT = Path(__file__).resolve().parent.parent
CASES = ("rough_terrain", "side_slope", "gnss_noise", "stop_and_go", "headland_turn", "dusty", "dense_dust",
         "high_flow", "grazing_sensor")


def _bench(name: str):
    spec = importlib.util.spec_from_file_location(name, ROOT / "bench" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_the_suite_sweeps_every_case_over_twenty_seeds_with_perception():
    sweep = load_sweep(ROOT / "bench" / "field_suite.yaml")
    assert sweep.labels == ("base",) and len(sweep.runs) == len(CASES) * 20
    assert [r.labels["base"] for r in sweep.runs[::20]] == list(CASES)
    for run in sweep.runs[::20]:
        case = load_scenario(packaged_scenarios()[run.labels["base"]], ["sensor.noise.range_sigma_m=0.01"],
                             extra={"renderer": "mock"})
        assert run.scenario.feedback == "perception" and run.scenario.renderer == "mock"
        assert run.scenario.model_copy(update={"outputs": case.outputs, "plugin_dir": case.plugin_dir}) == case
    assert sorted({r.seed for r in sweep.runs}) == list(range(20)) and len({r.id for r in sweep.runs}) == 180


def test_the_table_counts_outcomes_per_case_and_judges_the_acceptance(tmp_path):
    fs = _bench("field_suite")
    rows = ([{"base": "a", "outcome": "filled", "spill_kg": "0", "max_overfill_m": "0.01", "time_to_target_s": "90",
              "outcome_reason": ""}] * 19
            + [{"base": "a", "outcome": "stopped_safe", "spill_kg": "0", "max_overfill_m": "0.0",
                "outcome_reason": "perception never found the cart: 0 of 1201 frames; ..."}]
            + [{"base": "b", "outcome": "job_failed", "spill_kg": "12.5", "max_overfill_m": "0.07",
                "outcome_reason": "overfill 7 cm in section 9"}])
    table = fs.summarize_results(rows)
    assert table["a"]["filled_share"] == 0.95 and table["a"]["meets"] and not table["b"]["meets"]
    assert table["a"]["reasons"] == {"perception never found the cart: # of # frames": 1}
    md = fs.render_markdown(table, {"runs": 21, "results": "runs/x", "written": "now"})
    assert "| `a` | 20 | 95 % | 5 % | 0 % | 0 | 1.0 / 1.0 | 90 | yes |" in md
    results = tmp_path / "results.md"
    results.write_text("# Current benchmark results\n\nheadline\n")
    fs.put_section(results, md)
    fs.put_section(results, md)                                      # replaced, not appended twice
    assert results.read_text().count(fs.SECTION) == 1
    assert _bench("run_all").kept_suite_section(results).strip().startswith(fs.SECTION)
