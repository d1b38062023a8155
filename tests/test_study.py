"""The error-against-run-time study: overrides, references, outputs."""
from __future__ import annotations

import csv

import pytest

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


def test_grain_cell_study_runs_and_measures_against_the_finest_cell(tmp_path):
    sc = Scenario(format_version=1, feedback="ground_truth", renderer="none")
    md = run_study(sc, ["grain_cell"], tmp_path, duration_s=3.0)
    rows = list(csv.DictReader(open(tmp_path / "results.csv")))
    assert [r["setting"] for r in rows] == ["cell=0.2", "cell=0.1", "cell=0.05"]
    errors = {r["setting"]: float(r["error"]) for r in rows}
    assert errors["cell=0.05"] == 0.0
    assert all(0.0 <= e < 0.2 for e in errors.values())
    assert (tmp_path / "study.png").stat().st_size > 1000 and "default" in md.read_text()
