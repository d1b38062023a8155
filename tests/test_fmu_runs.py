"""FMUs in the loop against the built-in models, and FMU faults during a run (docs/fmu.md).

The FMUs are built once per session (tests/fmu_builds.py): with pythonfmu (FMI 2.0) the example vehicle (RK4
tractor-cart), the example controller (section fill, front to back) and the test-only strategy (front_to_back) and
faulty vehicle; with pythonfmu3 (FMI 3.0) the same vehicle and the strategy with array variables; in C (FMI 3.0)
the strategy with an input clock. Runs are ground-truth feedback without a renderer, in-process (cosim.runtime.inprocess.simulate) unless
the test is about the launched process ring.
"""
from __future__ import annotations

import importlib.util
import json
import shutil
from pathlib import Path

import fmu_builds
import numpy as np
import pytest

from cosim.cli import main
from cosim.errors import PluginFault, ScenarioError
from cosim.fmi.slave import FmuStepError
from cosim.runtime.inprocess import simulate
from cosim.scenario.loader import load_scenario

EXAMPLES = fmu_builds.ROOT / "examples"
#: a demanding path for the vehicle: a 60 m arc, the cart 1.5 m behind and 0.8 m beside its setpoint at t = 0
#: (steering and both lags active, their rate limits hit)
MANOEUVRE = ["combine.path=arc", "combine.path_radius_m=60.0", "machine_sync.initial_lat_error_m=0.8",
             "machine_sync.initial_long_error_m=-1.5"]
VEHICLE_COLUMNS = ("tractor_x_m", "tractor_y_m", "cart_x_m", "cart_y_m")
YAW_COLUMNS = ("tractor_yaw_rad", "cart_yaw_rad")
#: the FMU vehicle against the built-in RK4 model: the same equations, the same RK4 scheme, the same dt and the
#: same held Machine Sync input, so the states differ only by rounding and by the combine, which the FMU path
#: advances exactly (vehicles.combine_advance) where the built-in integrates it with RK4 (local error ~ (yaw
#: rate x dt)^5 x radius ~ 1e-23 m). Measured 1.8e-12 m over 30 s; bound 1e-9 m (m and rad)
RK4_TOL = 1e-9
#: against the default built-in integrator (exact lags, RK4 kinematics) the FMU's RK4 lags differ by RK4's
#: truncation error, O(dt^4) in smooth stretches and O(dt^2) where a rate limit switches (kinks within a step);
#: measured 8e-7 m over 30 s; bound 1e-5 m
EXPONENTIAL_TOL = 1e-5


def _place(tmp_path: Path, built: dict, example: str, fmu: str) -> Path:
    """The example's scenario.yaml in ``tmp_path`` with the built FMU beside it, as the example folder has it."""
    shutil.copy(EXAMPLES / example / "scenario.yaml", tmp_path / "scenario.yaml")
    shutil.copy(built[fmu], tmp_path / f"{fmu}.fmu")
    return tmp_path / "scenario.yaml"


def _series(path: Path, overrides=()) -> dict[str, np.ndarray]:
    return simulate(load_scenario(path, list(overrides))).recorder.series()


@pytest.mark.parametrize("name", ["TractorCart", "TractorCart3"])
def test_fmu_vehicle_reproduces_builtin_trajectory(tmp_path, built_fmus, name):
    """The example vehicle as an FMI 2.0 (pythonfmu) and an FMI 3.0 (pythonfmu3) FMU: the same equations, the same
    tolerances."""
    path = _place(tmp_path, built_fmus, "fmu_vehicle", "TractorCart")
    fmu = _series(path, MANOEUVRE + [f"vehicles.tractor_cart.fmu.path={fmu_builds.need(built_fmus, name)}"])
    rk4 = _series(path, MANOEUVRE + ["vehicles.tractor_cart.fmu=null", "integrator.method=rk4"])
    exp = _series(path, MANOEUVRE + ["vehicles.tractor_cart.fmu=null"])
    assert fmu["dyn_state.t_s"][-1] == pytest.approx(30.0)
    # the manoeuvre is not trivial: the cart turns, the tractor speeds up and steers to close its initial error
    assert np.ptp(fmu["dyn_state.cart_yaw_rad"]) > 0.4 and np.ptp(fmu["dyn_state.tractor_speed_mps"]) > 0.3
    assert np.ptp(fmu["dyn_state.tractor_steer_rad"]) > 0.05
    for c in VEHICLE_COLUMNS + YAW_COLUMNS:
        k = f"dyn_state.{c}"
        assert np.max(np.abs(fmu[k] - rk4[k])) < RK4_TOL, c
        assert np.max(np.abs(fmu[k] - exp[k])) < EXPONENTIAL_TOL, c
    np.testing.assert_array_equal(fmu["dyn_state.target_section"], rk4["dyn_state.target_section"])


def test_fmu_vehicle_stepped_per_frame(tmp_path, built_fmus):
    """``step: frame``: one doStep of the sensor period per frame, Machine Sync's command held over it: the same as
    the built-in RK4 model with one dynamics step per frame (the flow model still steps every 10 ms)."""
    path = _place(tmp_path, built_fmus, "fmu_vehicle", "TractorCart")
    per_frame = _series(path, MANOEUVRE + ["vehicles.tractor_cart.fmu.step=frame", "duration_s=10"])
    per_step = _series(path, MANOEUVRE + ["duration_s=10"])
    coarse = _series(path, MANOEUVRE + ["duration_s=10", "vehicles.tractor_cart.fmu=null", "integrator.method=rk4",
                                        "timing.dynamics_dt_s=0.1"])
    k = "dyn_state.cart_x_m"
    assert np.max(np.abs(per_frame[k] - coarse[k])) < RK4_TOL
    assert np.max(np.abs(per_frame[k] - per_step[k])) > 1e-4      # a real difference: held over 10x longer


#: strategy FMU -> its mapping: FMI 2.0 scalars per section ({k}), numbered 1..N or, with index_base: 0, 0..N-1
#: (answers -1 for none); FMI 3.0 arrays (the section vectors as one variable each, Float64 heights and an Int64
#: current section); FMI 3.0 in C with a triggered input clock
STRATEGY_MAPPINGS = {
    "FrontToBack": "{full: 'full_{k}', current_section: current}",
    "FrontToBack0": "{full: 'full_{k}', current_section: current}\n    index_base: 0",
    "FrontToBack3": "{full: full, height_m: height, current_section: current}",
    "Clocked": "{full: full}",
}


def _strategy_scenario(tmp_path: Path, built: dict, name: str, duration_s: float) -> Path:
    shutil.copy(fmu_builds.need(built, name), tmp_path / "Strategy.fmu")
    path = tmp_path / "scenario.yaml"
    path.write_text(f"format_version: 1\nduration_s: {duration_s}\nfeedback: ground_truth\nrenderer: none\n"
                    "controller:\n  strategy: fmu\n  fmu:\n    path: Strategy.fmu\n"
                    f"    inputs: {STRATEGY_MAPPINGS[name]}\n    outputs: {{section: section}}\n")
    return path


@pytest.mark.parametrize("name", list(STRATEGY_MAPPINGS))
def test_fmu_strategy_reproduces_front_to_back(tmp_path, built_fmus, name):
    path = _strategy_scenario(tmp_path, built_fmus, name, 60.0)
    s = load_scenario(path)
    fmu = simulate(s)
    builtin = simulate(load_scenario(path, ["controller.strategy=front_to_back", "controller.fmu=null"]))
    a, b = fmu.recorder.series(), builtin.recorder.series()
    assert np.max(a["dyn_state.target_section"]) >= 4                   # several sections filled in turn
    for k in a:
        if k.startswith("dyn_state."):
            np.testing.assert_array_equal(a[k], b[k], err_msg=k)
    np.testing.assert_array_equal(fmu.recorder.arrays["heightmap_truth"], builtin.recorder.arrays["heightmap_truth"])


def test_fmu_controller_reproduces_builtin_paper_controller(tmp_path, built_fmus):
    path = _place(tmp_path, built_fmus, "fmu_controller", "SectionFill")
    fmu = _series(path)
    builtin = _series(path, ["controller.model=section_fill", "controller.fmu=null", "controller.estimator=paper"])
    assert fmu["dyn_state.nudge_count"][-1] >= 5 and np.max(fmu["dyn_state.target_section"]) >= 5
    # what the built-in reports of its coping (docs/field.md) the FMU does not: every other column is equal
    coping = {f"dyn_state.{c}" for c in ("control_mode", "hold_reason", "estimate_sigma_m", "full_lead_m")}
    for k in fmu:
        if k.startswith("dyn_state.") and k not in coping:
            np.testing.assert_array_equal(fmu[k], builtin[k], err_msg=k)


@pytest.mark.parametrize("name", ["FrontToBack", "FrontToBack0"])
def test_fmu_strategy_answers_none_when_every_section_is_full(tmp_path, built_fmus, name):
    """A cart filled to the target from the start: the FMU answers 'none' (0 with index_base 1, -1 with index_base 0)
    from the first measurement on, the auger never runs, as with the built-in strategy."""
    path = _strategy_scenario(tmp_path, built_fmus, name, 3.0)
    full = ["grain.initial_fill_m=1.9"]
    a = _series(path, full)
    b = _series(path, full + ["controller.strategy=front_to_back", "controller.fmu=null"])
    assert a["dyn_state.all_full"][-1] == 1 and not a["dyn_state.auger_on"].any()
    assert (a["dyn_state.target_section"] == 0).all()                  # none, in the table's 1..N numbering
    for k in a:
        if k.startswith("dyn_state."):
            np.testing.assert_array_equal(a[k], b[k], err_msg=k)


def test_zero_based_fmu_without_index_base_is_refused(tmp_path, built_fmus):
    path = _strategy_scenario(tmp_path, built_fmus, "FrontToBack0", 3.0)
    path.write_text(path.read_text().replace("    index_base: 0\n", ""))
    with pytest.raises(ScenarioError) as e:
        load_scenario(path)
    (p,) = e.value.problems
    assert p.path == "controller.fmu.inputs.full" and p.message.startswith("no variable 'full_9' in the FMU")


def test_section_answers_follow_index_base():
    """The adapter's reading of an FMU's section answer: base 1 (1..N, 0 none) and base 0 (0..N-1, -1 none) give
    the same 0-based index; out of range is a fault naming the range."""
    from dynamics_proc.fmu.models import _section

    slave = type("S", (), {"desc": type("D", (), {"path": "X.fmu"}), "label": "controller.fmu"})()
    assert [_section(slave, v, 9, "section", 1, 1) for v in (1.0, 9.0, 0.0)] == [0, 8, -1]
    assert [_section(slave, v, 9, "section", 1, 0) for v in (0.0, 8.0, -1.0)] == [0, 8, -1]
    with pytest.raises(FmuStepError, match=r"output 'section' is 9, not a section 0..8 or -1 \(none\)"):
        _section(slave, 9.0, 9, "section", 3, 0)
    with pytest.raises(FmuStepError, match=r"output 'section' is -1, not a section 1..9 or 0 \(none\)"):
        _section(slave, -1.0, 9, "section", 3, 1)


def _faulty(tmp_path: Path, built: dict, mode: int) -> Path:
    """The vehicle example with the faulty FMU in place of the tractor: it fails at t = 0.55 s (frame 6)."""
    path = _place(tmp_path, built, "fmu_vehicle", "Faulty")
    text = path.read_text().replace("TractorCart.fmu", "Faulty.fmu")
    head, _, _ = text.partition("      parameters:")
    path.write_text(head + f"      parameters: {{mode: {mode}, fail_at_s: 0.55}}\n")
    return path


@pytest.mark.parametrize("mode, cause", [(1, "doStep: fmi2DoStep failed with status 2"), (2, "output 'x' is nan")])
def test_fmu_fault_names_file_and_frame(tmp_path, built_fmus, mode, cause):
    path = _faulty(tmp_path, built_fmus, mode)
    with pytest.raises(FmuStepError, match=rf"FMU {tmp_path / 'Faulty.fmu'} \(vehicles.tractor_cart.fmu\) failed at "
                                           rf"frame 6 \(t = 0.550 s\): {cause}") as e:
        simulate(load_scenario(path))
    assert e.value.frame == 6


def test_fmu_strategy_bad_section_ends_run(tmp_path, built_fmus):
    shutil.copy(built_fmus["FrontToBack"], tmp_path / "FrontToBack.fmu")
    path = tmp_path / "scenario.yaml"
    path.write_text("format_version: 1\nduration_s: 2.0\nfeedback: ground_truth\nrenderer: none\n"
                    "controller:\n  strategy: fmu\n  fmu:\n    path: FrontToBack.fmu\n"
                    "    inputs: {full: 'full_{k}'}\n    outputs: {section: section}\n    parameters: {bad_section: 12}\n")
    with pytest.raises(PluginFault, match=r"plug-in controller.strategy = 'fmu' at frame 2: raised FmuStepError: FMU "
                                          r".*FrontToBack.fmu \(controller.fmu\) failed at frame 2: output 'section' is "
                                          r"12, not a section 1..9 or 0"):
        simulate(load_scenario(path))


def test_launched_fault_ends_run_cleanly(tmp_path, built_fmus, shm_clean):
    """Over the process ring: exit 1, the error names the dynamics process, the FMU and the frame; the run
    directory keeps the frames before it."""
    out = tmp_path / "run"
    assert main(["run", str(_faulty(tmp_path, built_fmus, 1)), "--out", str(out), "--quiet"]) == 1
    summary = json.loads((out / "summary.json").read_text())
    assert summary["completed"] is False and summary["frames"] == 6, summary
    err = summary["error"]
    assert err["frame"] == 6 and err["message"].startswith("dynamics raised FmuStepError at frame 6: FMU ")
    assert f"{tmp_path / 'Faulty.fmu'} (vehicles.tractor_cart.fmu) failed at frame 6 (t = 0.550 s): doStep" in \
        err["message"]


@pytest.mark.parametrize("example, fmu", [("fmu_vehicle", "TractorCart"), ("fmu_controller", "SectionFill")])
def test_example_builds_and_runs_launched(tmp_path, built_fmus, shm_clean, example, fmu):
    """What the example's README says: build.py makes the FMU, the scenario runs as is (briefly here)."""
    spec = importlib.util.spec_from_file_location(f"build_{example}", EXAMPLES / example / "build.py")
    build = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(build)
    assert build.build(tmp_path) == tmp_path / f"{fmu}.fmu"
    if example == "fmu_vehicle" and not fmu_builds.MISSING3:
        assert build.build3(tmp_path) == tmp_path / "TractorCart3.fmu"
    shutil.copy(EXAMPLES / example / "scenario.yaml", tmp_path / "scenario.yaml")
    assert main(["run", str(tmp_path / "scenario.yaml"), "--duration", "5", "--out", str(tmp_path / "run"),
                 "--quiet"]) == 0
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["completed"] is True and summary["frames"] == 51


def test_adapters_follow_the_roles_signal_order():
    """The adapters read the FMU's values by position in the role's signal order (cosim.fmi.roles)."""
    from cosim.fmi.roles import CONTROLLER, VEHICLE
    from dynamics_proc.fmu import models as fmus

    assert list(fmus._STATE_INDEX) == [s.name for s in VEHICLE.outputs]
    assert list(fmus._CONTROLLER_INPUTS) == [s.name for s in CONTROLLER.inputs[1:]]
    assert CONTROLLER.inputs[0].name == "height_m" and CONTROLLER.outputs[-1].per_section
