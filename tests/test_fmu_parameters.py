"""FMU parameters as ordinary scenario keys (docs/fmu.md): ``--set ...fmu.parameters.NAME=VALUE`` merges into the
record's parameters, is checked against the FMU's model description (name, type, declared range) at its own
``<--set>`` position, and a sweep varies one parameter like any field, with a results.csv column of its own."""
from __future__ import annotations

import csv
import shutil
from pathlib import Path

import fmu_builds
import numpy as np
import pytest

from cosim.cli import main
from cosim.errors import ScenarioError
from cosim.runtime.inprocess import simulate
from cosim.scenario.loader import SET_FILE, load_scenario

pytest.importorskip("distributed")

EXAMPLE = fmu_builds.ROOT / "examples" / "fmu_vehicle" / "scenario.yaml"
KEY = "vehicles.tractor_cart.fmu.parameters"
#: the FMU against the built-in RK4 model with the same parameter (tests/test_fmu_runs.py: measured ~2e-12 m)
RK4_TOL = 1e-9
#: an initial error, so that the drivetrain lag shapes the trajectory
MANOEUVRE = ["machine_sync.initial_long_error_m=-1.5", "duration_s=10"]


def _place(tmp_path: Path, fmu: Path) -> Path:
    shutil.copy(EXAMPLE, tmp_path / "scenario.yaml")
    shutil.copy(fmu, tmp_path / "TractorCart.fmu")
    return tmp_path / "scenario.yaml"


def _ranged(built: dict, tmp_path: Path) -> Path:
    """The example vehicle FMU with a declared range on drivetrain_tau_s: [0.05, 2.0] s."""
    return fmu_builds.variant(built["TractorCart"], tmp_path / "ranged.fmu", lambda t: t.replace(
        'name="drivetrain_tau_s"', 'name="drivetrain_tau_s" description="drivetrain lag"', 1)
        .replace('<Real start="0.5"', '<Real min="0.05" max="2.0" start="0.5"', 1))


def test_set_one_parameter_merges_and_runs_as_the_builtin_with_it(tmp_path, built_fmus):
    """``--set`` reaches one key of the FMU's parameters, keeps the others, and the FMU then runs as the built-in
    model given the same value (tractor.drivetrain_tau_s)."""
    path = _place(tmp_path, built_fmus["TractorCart"])
    s = load_scenario(path, MANOEUVRE + [f"{KEY}.drivetrain_tau_s=1.2"])
    assert dict(s.vehicles.tractor_cart.fmu.parameters) == {"wheelbase_m": 3.0, "hitch_offset_m": 1.5,
                                                           "tow_length_m": 8.08, "drivetrain_tau_s": 1.2, "substeps": 1}
    fmu = simulate(s).recorder.series()
    builtin = simulate(load_scenario(path, MANOEUVRE + ["vehicles.tractor_cart.fmu=null", "integrator.method=rk4",
                                                       "tractor.drivetrain_tau_s=1.2"])).recorder.series()
    default = simulate(load_scenario(path, MANOEUVRE)).recorder.series()
    k = "dyn_state.cart_x_m"
    assert np.max(np.abs(fmu[k] - builtin[k])) < RK4_TOL
    assert np.max(np.abs(fmu[k] - default[k])) > 1e-2           # the parameter changed the run


@pytest.mark.parametrize("override, message", [
    (f"{KEY}.steer_zeta=0.7", "no variable 'steer_zeta' in the FMU TractorCart.fmu (did you mean 'steer_tau_s'?)"),
    (f"{KEY}.substeps=0.5", "FMU parameter 'substeps' is Integer, got 0.5"),
    (f"{KEY}.drivetrain_tau_s=true", "FMU parameter 'drivetrain_tau_s' is Real, got True"),
    (f"{KEY}.drivetrain_tau_s=2.5", "FMU parameter 'drivetrain_tau_s' must be within [0.05, 2.0] (its range in the "
                                    "FMU's model description), got 2.5"),
    (f"{KEY}.x=1.0", "FMU variable 'x' has causality 'output'; it must be 'parameter' here"),
])
def test_parameter_checked_against_the_model_description(tmp_path, built_fmus, override, message):
    path = _place(tmp_path, _ranged(built_fmus, tmp_path))
    with pytest.raises(ScenarioError) as e:
        load_scenario(path, [override])
    (p,) = e.value.problems
    name = override.split("=")[0]
    assert (p.file, p.line, p.col, p.path, p.message) == (SET_FILE, 1, len(name) + 2, name, message)


def test_sweep_over_one_parameter_has_it_as_a_column(tmp_path, built_fmus):
    """A 3-point grid over one FMU parameter: three runs, each with its value in its scenario.yaml, its row in
    results.csv with the parameter's column, and different trajectories."""
    _place(tmp_path, built_fmus["TractorCart"])
    values = [0.3, 0.6, 1.2]
    (tmp_path / "sweep.yaml").write_text(
        "format_version: 1\nname: tau\nbase: scenario.yaml\n"
        "set: {duration_s: 3.0, machine_sync.initial_long_error_m: -1.5}\n"
        f"grid:\n  {KEY}.drivetrain_tau_s: {values}\nseeds: [0]\n")
    out = tmp_path / "out"
    assert main(["sweep", str(tmp_path / "sweep.yaml"), "--jobs", "1", "--out", str(out), "--quiet"]) == 0
    with open(out / "results.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    column = f"{KEY}.drivetrain_tau_s"
    assert sorted(float(r[column]) for r in rows) == values and all(r["completed"] == "True" for r in rows)
    ends = set()
    for r in rows:
        run = out / "runs" / r["id"]
        s = load_scenario(run / "scenario.yaml")
        assert s.vehicles.tractor_cart.fmu.parameters["drivetrain_tau_s"] == float(r[column])
        with open(run / "timeseries.csv", newline="") as f:
            ends.add(list(csv.DictReader(f))[-1]["dyn_state.cart_x_m"])
    assert len(ends) == 3


def test_sweep_value_out_of_range_is_reported_at_the_sweep_line(tmp_path, built_fmus, capsys):
    _place(tmp_path, _ranged(built_fmus, tmp_path))
    (tmp_path / "sweep.yaml").write_text(
        "format_version: 1\nbase: scenario.yaml\n"
        f"grid:\n  {KEY}.drivetrain_tau_s: [0.5, 3.0]\n")
    assert main(["sweep", str(tmp_path / "sweep.yaml"), "--out", str(tmp_path / "out"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert (f"sweep.yaml:4:{len(KEY) + len('.drivetrain_tau_s') + 11}: grid.{KEY}.drivetrain_tau_s[1]: FMU "
            "parameter 'drivetrain_tau_s' must be within [0.05, 2.0]") in err, err
    assert not (tmp_path / "out").exists()
