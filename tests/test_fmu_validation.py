"""FMU problems found when a scenario is loaded: each a ScenarioError entry ``file:line:col: key: message`` at
the line of the offending value, every one at once, nothing started (docs/fmu.md)."""
from __future__ import annotations

import shutil
import sys
from pathlib import Path

import fmu_builds
import pytest

from cosim.cli import main
from cosim.errors import ScenarioError
from cosim.fmi.describe import FmiUnavailable, describe, require_fmpy
from cosim.scenario.loader import load_scenario

EXAMPLES = fmu_builds.ROOT / "examples"
VEHICLE_TEXT = (EXAMPLES / "fmu_vehicle" / "scenario.yaml").read_text()
CONTROLLER_TEXT = (EXAMPLES / "fmu_controller" / "scenario.yaml").read_text()


def _scenario(tmp_path: Path, built: dict, text: str, fmu: str = "TractorCart", name: str | None = None) -> Path:
    """The scenario ``text`` in ``tmp_path`` with FMU ``fmu`` beside it (as ``name``, default its own)."""
    shutil.copy(built[fmu], tmp_path / (name or f"{fmu}.fmu"))
    path = tmp_path / "scenario.yaml"
    path.write_text(text)
    return path


def _problems(path: Path, **kw) -> list:
    with pytest.raises(ScenarioError) as e:
        load_scenario(path, **kw)
    return e.value.problems


def _line_of(text: str, needle: str) -> int:
    """1-based line of ``needle``: the line that is exactly it (stripped), else the first that holds it."""
    lines = text.splitlines()
    exact = [i for i, line in enumerate(lines, 1) if line.strip() == needle.strip()]
    return exact[0] if exact else next(i for i, line in enumerate(lines, 1) if needle in line)


def _one(problems, key: str):
    found = [p for p in problems if p.path == key]
    assert len(found) == 1, problems
    return found[0]


@pytest.mark.parametrize("old, new, key, message", [
    ("speed_cmd_mps: v_cmd", "speed_cmd_mps: v_cmdd", "vehicles.tractor_cart.fmu.inputs.speed_cmd_mps",
     "no variable 'v_cmdd' in the FMU TractorCart.fmu (did you mean 'v_cmd'?)"),
    ("tractor_axle_x_m: x\n", "tractor_axle_x_m: v_cmd\n", "vehicles.tractor_cart.fmu.outputs.tractor_axle_x_m",
     "FMU variable 'v_cmd' has causality 'input'; it must be 'output' here"),
    ("steer_cmd_rad: delta_cmd", "steer_cmd_rad: delta", "vehicles.tractor_cart.fmu.inputs.steer_cmd_rad",
     "FMU variable 'delta' has causality 'output'; it must be 'input' here"),
    ("tractor_axle_y_m: y0", "tractor_axle_y_m: cart_yaw", "vehicles.tractor_cart.fmu.initial.tractor_axle_y_m",
     "FMU variable 'cart_yaw' has causality 'output'; it must be 'parameter' or 'input' here"),
    ("speed_cmd_mps: v_cmd", "speed_cmd: v_cmd", "vehicles.tractor_cart.fmu.inputs.speed_cmd",
     "no input signal 'speed_cmd' (did you mean 'speed_cmd_mps'?) for the vehicles.tractor_cart FMU"),
    ("wheelbase_m: 3.0", "wheelbase: 3.0", "vehicles.tractor_cart.fmu.parameters.wheelbase",
     "no variable 'wheelbase' in the FMU TractorCart.fmu (did you mean 'wheelbase_m'?)"),
    ("substeps: 1", "substeps: 1.5", "vehicles.tractor_cart.fmu.parameters.substeps",
     "FMU parameter 'substeps' is Integer, got 1.5"),
    ("substeps: 1", "x: 1.0", "vehicles.tractor_cart.fmu.parameters.x",
     "FMU variable 'x' has causality 'output'; it must be 'parameter' here"),
])
def test_vehicle_mapping_problem_at_its_line(tmp_path, built_fmus, old, new, key, message):
    assert old in VEHICLE_TEXT
    text = VEHICLE_TEXT.replace(old, new)
    p = _one(_problems(_scenario(tmp_path, built_fmus, text)), key)
    assert p.message.startswith(message), p.message
    assert p.line == _line_of(text, new.strip()) and p.file == str(tmp_path / "scenario.yaml")


def test_missing_required_output_and_every_problem_at_once(tmp_path, built_fmus):
    text = VEHICLE_TEXT.replace("        cart_yaw_rad: cart_yaw\n", "").replace("v_cmd\n", "speed\n")
    problems = _problems(_scenario(tmp_path, built_fmus, text))
    assert _one(problems, "vehicles.tractor_cart.fmu.outputs").message == (
        "the vehicles.tractor_cart FMU needs outputs 'cart_yaw_rad' mapped (our name: FMU variable name)")
    assert "no variable 'speed'" in _one(problems, "vehicles.tractor_cart.fmu.inputs.speed_cmd_mps").message


def test_missing_file(tmp_path, built_fmus):
    text = VEHICLE_TEXT.replace("path: TractorCart.fmu", "path: nowhere/Tractor.fmu")
    p = _one(_problems(_scenario(tmp_path, built_fmus, text)), "vehicles.tractor_cart.fmu.path")
    assert "nowhere/Tractor.fmu' does not exist" in p.message
    assert p.line == _line_of(text, "nowhere/Tractor.fmu")


@pytest.mark.parametrize("edit, message", [
    (lambda t: t.replace("<CoSimulation", "<ModelExchange"), "is a model-exchange FMU; graincosim steps "
                                                             "co-simulation FMUs only"),
    (lambda t: t.replace('fmiVersion="2.0"', 'fmiVersion="4.0"'), "is an FMI 4.0 FMU: FMI 4.0 is not supported; "
                                                                  "export it as FMI 2.0 or 3.0 co-simulation"),
    (lambda t: t.replace('fmiVersion="2.0"', 'fmiVersion="1.0"'), "is an FMI 1.0 FMU: FMI 1.0 is not supported"),
])
def test_wrong_kind_of_fmu(tmp_path, built_fmus, edit, message):
    bad = fmu_builds.variant(built_fmus["TractorCart"], tmp_path / "Bad.fmu", edit)
    path = _scenario(tmp_path, {"Bad": bad}, VEHICLE_TEXT, "Bad", "TractorCart.fmu")
    p = _one(_problems(path), "vehicles.tractor_cart.fmu.path")
    assert p.message == f"{tmp_path / 'TractorCart.fmu'} {message}" or message in p.message, p.message
    assert p.message.startswith(str(tmp_path / "TractorCart.fmu")) and message in p.message
    assert p.line == _line_of(VEHICLE_TEXT, "path: TractorCart.fmu")


def test_not_an_fmu(tmp_path):
    pytest.importorskip("fmpy", reason="FMU checks need fmpy (pip install -e \".[test]\")")
    (tmp_path / "TractorCart.fmu").write_text("not a zip")
    (tmp_path / "scenario.yaml").write_text(VEHICLE_TEXT)
    p = _one(_problems(tmp_path / "scenario.yaml"), "vehicles.tractor_cart.fmu.path")
    assert "is not an FMU (not a zip archive)" in p.message


def test_controller_fmu_problems(tmp_path, built_fmus):
    text = (CONTROLLER_TEXT.replace('height_m: "height_{k}"', "height_m: height")
            .replace("nudge: nudge", "nudge: spout_x")
            .replace("    path: SectionFill.fmu", "    step: dynamics_step\n    path: SectionFill.fmu"))
    problems = _problems(_scenario(tmp_path, built_fmus, text, "SectionFill"))
    assert _one(problems, "controller.fmu.inputs.height_m").message.startswith(
        "'height_m' is one value per section: the FMU name must hold {k}")
    assert _one(problems, "controller.fmu.outputs.nudge").message == (
        "FMU variable 'spout_x' has causality 'input'; it must be 'output' here")
    step = _one(problems, "controller.fmu.step")
    assert step.message == "the controller (model) FMU can only be stepped per frame"
    assert step.line == _line_of(text, "step: dynamics_step")


def test_fmu_named_but_not_given_and_given_but_unused(tmp_path, built_fmus):
    path = _scenario(tmp_path, built_fmus, "format_version: 1\ncontroller:\n  strategy: fmu\n")
    p = _one(_problems(path), "controller")
    assert p.message == "strategy 'fmu' needs the FMU: give controller.fmu (path, inputs, outputs)"
    text = CONTROLLER_TEXT.replace("  model: fmu", "  model: section_fill")
    p = _one(_problems(_scenario(tmp_path, built_fmus, text, "SectionFill")), "controller")
    assert p.message.startswith("controller.fmu is given but nothing uses it")


def test_no_plugins_refuses_fmus_and_validate_lists_them(tmp_path, built_fmus, capsys):
    path = _scenario(tmp_path, built_fmus, VEHICLE_TEXT)
    p = _one(_problems(path, allow_plugins=False), "vehicles.tractor_cart.fmu.path")
    assert p.message.endswith("an FMU runs its own binary code and plug-ins are refused (--no-plugins)")
    assert main(["validate", str(path), "--no-plugins"]) == 2
    assert main(["validate", str(path)]) == 0
    out = capsys.readouterr().out
    d = describe(tmp_path / "TractorCart.fmu")
    line = next(x for x in out.splitlines() if x.strip().startswith("fmu vehicles.tractor_cart.fmu"))
    assert (f"file {tmp_path / 'TractorCart.fmu'}; version FMI 2.0 co-simulation, model 'TractorCart', generated "
            f"by PythonFMU" in line and d.guid in line and "EXTERNAL" in line)


def test_scenario_with_fmu_is_hashable(tmp_path, built_fmus):
    """Frozen records are cache keys (the renderer's scene parts): the FMU record's mappings hash by content."""
    path = _scenario(tmp_path, built_fmus, CONTROLLER_TEXT, "SectionFill")
    a, b = load_scenario(path), load_scenario(path)
    assert a == b and hash(a) == hash(b)
    c = load_scenario(path, ["controller.fmu.parameters={nudge_m: 0.25}"])
    assert c != a and hash(c.controller.fmu) != hash(a.controller.fmu)


def test_fmpy_missing_says_what_to_install(monkeypatch):
    monkeypatch.setitem(sys.modules, "fmpy", None)            # import fmpy now raises ImportError
    with pytest.raises(FmiUnavailable, match=r'FMUs need fmpy, which is not installed: pip install "graincosim\[fmi\]"'):
        require_fmpy()
