"""The error-against-run-time study: overrides, references, outputs."""
from __future__ import annotations

import csv
import json

import pytest
import yaml

from cosim.cli import main
from cosim.scenario.config import Scenario
from cosim.studies.study import KNOBS, apply_overrides, run_study


def test_apply_overrides_validates_and_refuses_unknown_paths():
    sc = Scenario(format_version=1)
    out = apply_overrides(sc, {"grain.cell_m": 0.05, "timing.dynamics_dt_s": 0.02})
    assert out.grain.cell_m == 0.05 and out.timing.steps_per_frame == 5
    with pytest.raises(KeyError, match="no such field"):
        apply_overrides(sc, {"grain.nope": 1.0})


def test_every_knob_names_its_default_and_references():
    for knob in KNOBS.values():
        labels = {s.label for s in knob.settings}
        assert knob.default in labels, knob.name
        if isinstance(knob.reference, str):
            assert knob.reference in labels
        elif callable(knob.reference):
            assert all(knob.reference(s.label) in labels for s in knob.settings)


def test_grain_cell_study_runs_as_a_sweep_and_measures_against_the_finest_cell(tmp_path):
    sc = Scenario(format_version=1, feedback="ground_truth", renderer="none")
    md = run_study(sc, ["grain_cell"], tmp_path, duration_s=3.0)
    rows = list(csv.DictReader(open(tmp_path / "study.csv")))
    assert [r["setting"] for r in rows] == ["cell=0.2", "cell=0.1", "cell=0.05"]
    errors = {r["setting"]: float(r["error"]) for r in rows}
    assert errors["cell=0.05"] == 0.0
    assert all(0.0 <= e < 0.2 for e in errors.values())
    assert (tmp_path / "study.png").stat().st_size > 1000 and "default" in md.read_text()
    # the same engine and table as a sweep: one launched run per setting, its overrides in the scenario it ran
    runs = list(csv.DictReader(open(tmp_path / "results.csv")))
    assert [(r["knob"], r["setting"], r["completed"]) for r in runs] == [
        ("grain_cell", s, "True") for s in ("cell=0.2", "cell=0.1", "cell=0.05")]
    for r in runs:
        ran = yaml.safe_load((tmp_path / r["run_dir"] / "scenario.yaml").read_text())
        assert ran["grain"]["cell_m"] == float(r["grain.cell_m"]) == ran["controller"]["grid_cell_m"]
        assert ran["duration_s"] == 3.0 and float(r["sim_time_s"]) == pytest.approx(3.0)
    # the error is the section mean heights' largest difference, recomputed here from the summaries
    heights = {r["setting"]: json.loads((tmp_path / r["run_dir"] / "summary.json").read_text())
               ["fill"]["section_mean_height_m"] for r in runs}
    ref = heights["cell=0.05"]
    for label, h in heights.items():
        assert errors[label] == pytest.approx(max(abs(a - b) for a, b in zip(h, ref)), abs=1e-12)


def test_user_knob_from_the_command_line(tmp_path, capsys):
    out = tmp_path / "study"
    assert main(["study", "--renderer", "none", "--feedback", "ground_truth", "--knobs", "", "--sim-seconds", "3",
                 "--knob", "cell=grain.cell_m:0.2,0.05", "--out", str(out), "--quiet"]) == 0
    assert "study written to" in capsys.readouterr().out
    rows = {r["setting"]: r for r in csv.DictReader(open(out / "study.csv"))}
    assert set(rows) == {"cell_m=0.2", "cell_m=0.05"} and rows["cell_m=0.05"]["reference"] == "True"
    runs = {r["setting"]: r for r in csv.DictReader(open(out / "results.csv"))}
    h = {k: json.loads((out / r["run_dir"] / "summary.json").read_text())["fill"]["section_mean_height_m"]
         for k, r in runs.items()}
    expected = max(abs(a - b) for a, b in zip(h["cell_m=0.2"], h["cell_m=0.05"]))
    assert expected > 0 and float(rows["cell_m=0.2"]["error"]) == pytest.approx(expected, abs=1e-12)
    assert float(rows["cell_m=0.05"]["error"]) == 0.0


def test_bad_user_knobs_are_rejected_before_any_run(tmp_path, capsys):
    assert main(["study", "--knobs", "", "--knob", "x=combine.speed_mps:1.0", "--out", str(tmp_path / "a")]) == 2
    assert "<--knob>:1:1: <root>: malformed knob 'x=combine.speed_mps:1.0'" in capsys.readouterr().err
    assert main(["study", "--knobs", "", "--knob", "x=combine.nope:1.0,2.0", "--out", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err
    assert "<--knob>:1:1: x.nope=1.0: study override 'combine.nope': no such field" in err
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()
