"""bench/cases/scenarios.py: the ratios to the default run, the targets' verdicts and its results.md section, which
bench/run_all.py keeps beside the other commands' sections (fast: no run is launched)."""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT / "bench") not in sys.path:
    sys.path.insert(0, str(ROOT / "bench"))

from cases import scenarios as sc  # noqa: E402


def _row(wall: float, cpu: float, per_frame: float, rt: float) -> dict:
    return {"wall s": wall, "CPU s": cpu, "CPU ms/frame": per_frame, "real-time factor (ring)": rt}


def test_ratios_are_to_the_same_repeats_default_and_verdicts_name_each_target():
    base = _row(10.0, 20.0, 12.0, 6.0)
    tof = {**_row(25.0, 30.0, 48.0, 2.0)}
    tof.update(sc._ratios(tof, base))
    assert tof["wall / default"] == 2.5 and tof["CPU / default"] == 1.5 and tof["CPU per frame / default"] == 4.0
    assert sc._verdict("tof_mast", tof) == "wall <= 2x: NOT met; RT >= 3: NOT met"
    dusty = {**_row(14.0, 21.0, 13.0, 4.0)}
    dusty.update(sc._ratios(dusty, base))
    assert sc._verdict("dusty", dusty) == "wall <= 1.5x: met; RT >= 3: met"
    assert sc._verdict("default", {**base, **sc._ratios(base, base)}) == "RT >= 3: met"     # no wall target
    assert sc._ratios(_row(1.0, 1.0, None, 1.0), base)["CPU per frame / default"] is None


def test_medians_leave_out_missing_values():
    m = sc._median([{"a": 1.0, "b": None, "c": "x"}, {"a": 3.0, "b": None, "c": "y"}, {"a": 2.0, "b": None, "c": "z"}])
    assert m == {"a": 2.0, "b": None, "c": None}


def test_section_replaces_its_own_and_run_all_keeps_every_written_section(tmp_path):
    md = tmp_path / "results.md"
    md.write_text("# Current benchmark results\n\nheadline\n\n## Under load\n\nload table\n\n## Field-conditions suite\n\n"
                  "suite table\n")
    tables = {"packaged scenarios": {"default": {"wall s": 10.0, "targets": "RT >= 3: met"}}}
    sc.put_section(md, tables, 60.0, 2)
    sc.put_section(md, {"packaged scenarios": {"default": {"wall s": 11.0, "targets": "RT >= 3: met"}}}, 60.0, 2)
    text = md.read_text()
    assert text.count(sc.SECTION) == 1 and "| default | 11 | RT >= 3: met |" in text and "| 10 |" not in text
    assert "## Under load" in text and "suite table" in text
    spec = importlib.util.spec_from_file_location("run_all", ROOT / "bench" / "run_all.py")
    run_all = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(run_all)
    kept = run_all.kept_suite_section(md)
    assert sc.SECTION in kept and "## Under load" in kept and "## Field-conditions suite" in kept
    assert "headline" not in kept


def test_a_later_rounds_table_says_it_is_that_rounds_own(tmp_path):
    md = tmp_path / "results.md"
    tables = {"packaged scenarios": {"default": {"wall s": 10.0, "targets": "RT >= 3: met"}}}
    sc.put_section(md, tables, 60.0, 1)
    assert "round" not in md.read_text()
    sc.put_section(md, tables, 60.0, 1, round_index=1)
    assert "round 2, its own table" in md.read_text()
