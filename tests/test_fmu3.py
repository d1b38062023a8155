"""FMI 3.0 FMUs in the loop (docs/fmu.md): array variables, types, input clocks, and what is refused at validation.

The FMUs come from tests/fmu_builds.py: FrontToBack3 (pythonfmu3; Boolean and Float64 arrays of 9, an Int64 input),
TractorCart3 (pythonfmu3; the example vehicle) and Clocked / ClockedPeriodic (C; an input clock ``tick``, triggered
or constant at 0.1 s; the FMU returns fmi3Error when the master breaks FMI 3.0's calling sequence: a clocked
variable touched outside a tick, a doStep that does not start where the FMU stands, a tick off its period).
The reproductions of the built-in vehicle and strategy are in tests/test_fmu_runs.py.
"""
from __future__ import annotations

import math
import shutil
from pathlib import Path

import fmu_builds
import numpy as np
import pytest

from cosim.errors import PluginFault, ScenarioError
from cosim.fmi.describe import describe
from cosim.fmi.slave import FmuSlave
from cosim.runtime.inprocess import simulate
from cosim.scenario.loader import load_scenario

HEAD = "format_version: 1\nduration_s: {d}\nfeedback: ground_truth\nrenderer: none\n"
STRATEGY = HEAD + "controller:\n  strategy: fmu\n  fmu:\n    path: {fmu}.fmu\n    inputs: {inputs}\n" \
                  "    outputs: {{section: section}}\n"
CONTROLLER = HEAD + "controller:\n  model: fmu\n  fmu:\n    path: {fmu}.fmu\n    inputs: {{height_m: height}}\n" \
                    "    outputs: {{nudge: nudge, auger_on: auger_on, desired_x_m: tick_time}}\n" \
                    "    parameters: {{period_s: {period}, auger_until_s: 3.0}}\n"


def _write(tmp_path: Path, built: dict, fmu: str, text: str, src: str | None = None) -> Path:
    shutil.copy(src or fmu_builds.need(built, fmu), tmp_path / f"{fmu}.fmu")
    path = tmp_path / "scenario.yaml"
    path.write_text(text)
    return path


def _problems(path: Path, overrides=()) -> dict[str, str]:
    with pytest.raises(ScenarioError) as e:
        load_scenario(path, list(overrides))
    return {p.path: p.message for p in e.value.problems}


def test_describe_reads_types_shapes_and_clocks(built_fmus):
    d = describe(fmu_builds.need(built_fmus, "FrontToBack3"))
    assert d.fmi_version == "3.0" and d.generation_tool.startswith("PythonFMU3")
    v = d.variables
    assert (v["full"].type, v["full"].kind, v["full"].shape, v["full"].size) == ("Boolean", "Boolean", (9,), 9)
    assert (v["height"].type, v["height"].kind, v["height"].shape) == ("Float64", "Real", (9,))
    assert (v["current"].type, v["current"].kind, v["current"].shape) == ("Int64", "Integer", ())
    c = describe(fmu_builds.need(built_fmus, "ClockedPeriodic"))
    tick = c.variables["tick"]
    assert c.has_event_mode and [x.name for x in c.input_clocks()] == ["tick"]
    assert (tick.clock.interval_variability, tick.clock.interval_s) == ("constant", 0.1)


def test_slave_maps_arrays_to_flat_lists(built_fmus):
    """Inputs full (9 Booleans), height (9 Float64), current (Int64) are 19 places of the flat list, in that order;
    the FMU's answers show each array arrived whole and in order."""
    d = describe(fmu_builds.need(built_fmus, "FrontToBack3"))
    with FmuSlave(d, ["full", "height", "current"], ["section", "highest_height"], {"sections": 9}, "test") as s:
        full = [1.0, 1.0, 0.0] + [0.0] * 6
        height = [0.5, math.nan, 1.25, 0.0, 0.0, 0.0, 0.0, 0.0, 1.75]
        assert s.step(full + height + [0.0], 0.0, 0.1, 1) == [3.0, 1.75]
        assert s.step([1.0] * 9 + height + [0.0], 0.1, 0.1, 2) == [0.0, 1.75]      # all full: 0
        assert s.step(full + height + [1.0], 0.2, 0.1, 3) == [3.0, 1.75]           # current 1 is full: next


@pytest.mark.parametrize("inputs, sections, key, message", [
    ("{full: full, current_section: full}", 9, "controller.fmu.inputs.current_section",
     "FMU variable 'full' is Boolean; it must be Int32 or Int64 or Float64 here"),
    ("{full: current}", 9, "controller.fmu.inputs.full",
     "FMU variable 'current' is a scalar; a per-section signal maps to an array of 9 elements (one per section), or "
     "to one scalar per section with {k} in the name"),
    ("{full: full}", 8, "controller.fmu.inputs.full",
     "FMU variable 'full' is an array of shape (9,); a per-section signal maps to an array of 8 elements"),
    ("{full: 'full[{k}]'}", 9, "controller.fmu.inputs.full",
     "no variable 'full[1]' in the FMU FrontToBack3.fmu (did you mean 'full'?); FMI 3.0 arrays have no element "
     "names: map the whole array, 'full'"),
    ("{full: full, height_m: full}", 9, "controller.fmu.inputs.height_m",
     "FMU variable 'full' is Boolean; it must be Float64 here"),
])
def test_array_mapping_problems(tmp_path, built_fmus, inputs, sections, key, message):
    path = _write(tmp_path, built_fmus, "FrontToBack3", STRATEGY.format(d=5.0, fmu="FrontToBack3", inputs=inputs))
    problems = _problems(path, [f"controller.sections={sections}"])
    assert problems[key].startswith(message), problems


def test_unmapped_type_is_refused_by_name(tmp_path, built_fmus):
    """A Float32 (here: the FMU's height array re-declared) is an FMI 3.0 type graincosim does not map."""
    src = fmu_builds.variant(fmu_builds.need(built_fmus, "FrontToBack3"), tmp_path / "src.fmu",
                             lambda t: t.replace('<Float64 name="height"', '<Float32 name="height"')
                             .replace("</Float64>", "</Float32>"))
    path = _write(tmp_path, built_fmus, "FrontToBack3", STRATEGY.format(
        d=5.0, fmu="FrontToBack3", inputs="{full: full, height_m: height}"), src)
    assert _problems(path)["controller.fmu.inputs.height_m"] == (
        "FMU variable 'height' is Float32, a type graincosim does not map; use Float64")


def test_clocked_controller_ticks_once_per_frame_on_the_period(tmp_path, built_fmus):
    """The sensor frame ticks the FMU's constant 0.1 s clock at each decision time t_{m-1} (the FMU refuses a tick
    off its period and any clocked access outside a tick), and the tick's outputs drive frame m."""
    path = _write(tmp_path, built_fmus, "ClockedPeriodic", CONTROLLER.format(d=5.0, fmu="ClockedPeriodic",
                                                                                period=0.1))
    r = simulate(load_scenario(path)).recorder.series()
    t = r["dyn_state.t_s"]
    np.testing.assert_allclose(r["dyn_state.desired_auger_x_m"][1:], t[:-1], atol=1e-12)   # tick at t_{m-1}
    assert list(r["dyn_state.auger_on"][1:]) == [1.0 if x < 3.0 - 1e-9 else 0.0 for x in t[:-1]]
    assert r["dyn_state.nudge_count"][-1] == 0 and r["dyn_state.delivered_m3"][-1] > 0.0


def test_tick_refused_by_the_fmu_ends_the_run(tmp_path, built_fmus):
    """A clock the FMU ticks only every 0.3 s: its fmi3SetClock fails at t = 0.1 s, the run ends naming the FMU."""
    path = _write(tmp_path, built_fmus, "ClockedPeriodic", CONTROLLER.format(d=2.0, fmu="ClockedPeriodic",
                                                                                period=0.3))
    with pytest.raises(PluginFault, match=r"ClockedPeriodic.fmu \(controller.fmu\) failed at frame 2 \(t = 0.100 s\)"
                                          r": doStep: fmi3SetClock failed with status 3"):
        simulate(load_scenario(path))


def _clock_variant(tmp_path: Path, built: dict, edit) -> str:
    return str(fmu_builds.variant(fmu_builds.need(built, "Clocked"), tmp_path / "src.fmu", edit))


@pytest.mark.parametrize("fmu, edit, overrides, message", [
    ("ClockedPeriodic", None, ["timing.sensor_period_s=0.05"],
     "ClockedPeriodic.fmu: input clock 'tick' ticks every 0.1 s from 0.0 s; the sensor frame ticks every "
     "timing.sensor_period_s = 0.05 s from 0 s"),
    ("Clocked", lambda t: t.replace('hasEventMode="true"', ""), [],
     "Clocked.fmu declares the input clock 'tick' but not hasEventMode=\"true\" (a clock ticks in Event Mode)"),
    ("Clocked", lambda t: t.replace('intervalVariability="triggered"', 'intervalVariability="countdown"'), [],
     "Clocked.fmu: input clock 'tick' has intervalVariability 'countdown'; the controller (model) FMU's clock must be "
     "'triggered' or 'constant'"),
    ("Clocked", lambda t: t.replace('<Int32 name="ticks"', '<Clock name="tock" valueReference="11" causality="input" '
                                    'intervalVariability="triggered"/>\n    <Int32 name="ticks"'), [],
     "Clocked.fmu declares 2 input clocks ('tick', 'tock'); graincosim ticks one, the sensor frame"),
])
def test_controller_clock_problems(tmp_path, built_fmus, fmu, edit, overrides, message):
    src = _clock_variant(tmp_path, built_fmus, edit) if edit else None
    path = _write(tmp_path, built_fmus, fmu, CONTROLLER.format(d=2.0, fmu=fmu, period=0.0), src)
    assert _problems(path, overrides)["controller.fmu.path"].startswith(message)


def test_strategy_takes_a_triggered_clock_only(tmp_path, built_fmus):
    path = _write(tmp_path, built_fmus, "ClockedPeriodic", STRATEGY.format(d=2.0, fmu="ClockedPeriodic",
                                                                              inputs="{full: full}"))
    assert _problems(path)["controller.fmu.path"] == (
        "ClockedPeriodic.fmu: input clock 'tick' has intervalVariability 'constant'; the controller (strategy) FMU's "
        "clock must be 'triggered' (the sensor frame ticks it)")


def test_vehicle_takes_no_clock(tmp_path, built_fmus):
    """A vehicle FMU with an input clock is refused at its path, beside its other checks."""
    src = fmu_builds.variant(fmu_builds.need(built_fmus, "TractorCart3"), tmp_path / "src.fmu", lambda t: t.replace(
        "</ModelVariables>", '<Clock name="tick" valueReference="99" causality="input" '
                             'intervalVariability="triggered"/></ModelVariables>'))
    text = (fmu_builds.ROOT / "examples" / "fmu_vehicle" / "scenario.yaml").read_text()
    shutil.copy(src, tmp_path / "TractorCart.fmu")
    (tmp_path / "scenario.yaml").write_text(text)
    assert _problems(tmp_path / "scenario.yaml")["vehicles.tractor_cart.fmu.path"] == (
        "TractorCart.fmu declares the input clock 'tick'; the vehicles.tractor_cart FMU is stepped per dynamics step "
        "or frame and takes no clock")
