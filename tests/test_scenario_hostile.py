"""Hostile and implausible values: every value a scenario or ``--set`` can carry is checked before anything starts,
each refusal is exit 2 at its own key with file:line:col, never a traceback (docs/reliability.md, "Before anything
starts"). The property test is generated from the JSON Schema, so a field added later is covered without a change
here."""
from __future__ import annotations

import math

import pytest

from cosim.cli import main
from cosim.errors import ScenarioError
from cosim.scenario.config import Scenario
from cosim.scenario.config.limits import DIMENSIONLESS_MAX, UNITS, field_limits, unit_of
from cosim.scenario.jsonschema import scenario_json_schema
from cosim.scenario.loader import SET_FILE, load_scenario, load_scenario_text, resolve_scenario_arg
from cosim.scenario.yamlmarks import MAX_DEPTH

DEFAULT = resolve_scenario_arg("default")


def _numeric_fields(schema: dict) -> list[tuple[str, int | None]]:
    """(dotted key, tuple length or None) of every numeric property reachable from the root, from the schema."""
    defs = schema["$defs"]
    out = []

    def walk(body: dict, prefix: str) -> None:
        for key, prop in body.get("properties", {}).items():
            path = f"{prefix}{key}"
            branches = prop.get("anyOf", [prop])
            for b in branches:
                if "$ref" in b:
                    walk(defs[b["$ref"].split("/")[-1]], path + ".")
            if prop.get("prefixItems") and all(i.get("type") == "number" for i in prop["prefixItems"]):
                out.append((path, len(prop["prefixItems"])))
            elif any(b.get("type") in ("number", "integer") and not {"const", "enum"} & set(b) for b in branches):
                out.append((path, None))

    walk(schema, "")
    return out


FIELDS = _numeric_fields(scenario_json_schema())
HOSTILE = [".nan", ".inf", "-.inf", "1e308", "-1e308"]


def _problems(overrides: list[str]) -> list:
    try:
        load_scenario(DEFAULT, overrides)
    except ScenarioError as e:
        return e.problems
    return []


def test_the_schema_walk_finds_every_numeric_field():
    assert len(FIELDS) >= 100
    assert ("sensor.mount.rpy_deg", 3) in FIELDS and ("timing.sensor_period_s", None) in FIELDS
    assert ("controller.fusion.flow_meter_bias", None) in FIELDS and ("crop.density_kgpm3", None) in FIELDS


@pytest.mark.parametrize("path, size", FIELDS, ids=[p for p, _ in FIELDS])
def test_every_numeric_field_refuses_hostile_values_at_its_own_key(path, size):
    """NaN, inf, -inf, 1e308 and -1e308 (and malformed values) in every numeric field of the schema: refused at
    that field, at the override's position, never a traceback nor another key; a negative value is either valid or
    refused at the override."""
    def given(v: str) -> tuple[str, str]:
        if size is None:
            return f"{path}={v}", path
        return f"{path}=[{', '.join([v] + ['0'] * (size - 1))}]", f"{path}[0]"

    for value in HOSTILE + ['"abc"', "[1, [2]]", "{a: 1}"]:
        text, where = given(value)
        problems = _problems([text])
        assert problems, f"{text} was accepted"
        first = problems[0]
        assert first.file == SET_FILE and first.line == 1 and first.col >= 1, f"{text}: {first}"
        assert first.path in (where, path), f"{text}: refused at {first.path}, not {where}: {first}"
    problems = _problems([given("-1")[0]])
    assert all(p.file == SET_FILE for p in problems), problems


def test_nan_in_a_file_is_refused_at_its_key_and_never_reaches_a_child_as_null(tmp_path):
    path = tmp_path / "nan.yaml"
    path.write_text("format_version: 1\nsensor:\n  mount:\n    rpy_deg: [.nan, 60, 75]\ncontroller:\n"
                    "  strategy_options: {x: .inf}\n")
    with pytest.raises(ScenarioError) as info:
        load_scenario(path, check_world=False)
    assert [(p.line, p.col, p.path) for p in info.value.problems if "not a finite number" in p.message] == [
        (4, 15, "sensor.mount.rpy_deg[0]"), (6, 25, "controller.strategy_options.x")]
    with pytest.raises(ValueError, match="finite"):       # the record itself refuses NaN (a child re-validates)
        Scenario.model_validate_json('{"format_version": 1, "combine": {"heading_deg": NaN}}')


def test_implausible_values_are_refused_with_the_unit_named(capsys):
    """Milliseconds typed as seconds: 3 frames for a 200 s run, before; now refused at the override, unit named."""
    assert main(["validate", "default", "--set", "timing.sensor_period_s=100", "--set", "timing.dynamics_dt_s=1"]) == 2
    err = capsys.readouterr().err
    assert "<--set>:1:24: timing.sensor_period_s: Input should be less than or equal to 1 s, got 100 s" in err
    [problem] = _problems(["combine.speed_mps=500"])
    assert (problem.path, problem.col) == ("combine.speed_mps", 19)
    assert problem.message.startswith("500 m/s is above 100 m/s, beyond any machine")
    [problem] = _problems(["sensor.mount.xyz_m=[0, 0, 2e4]"])
    assert problem.path == "sensor.mount.xyz_m[2]" and problem.message.startswith("20000 m is above 10000 m")


def test_every_unit_suffix_bounds_its_fields():
    assert unit_of("sensor_period_s").symbol == "s" and unit_of("speed_mps").symbol == "m/s"
    assert unit_of("flow_m3ps").symbol == "m^3/s" and unit_of("steer_rate_max_degps").symbol == "deg/s"
    assert unit_of("kp_long") is None and len({u.suffix for u in UNITS}) == len(UNITS)
    from cosim.scenario.config import MachineSync, Tractor
    assert field_limits(MachineSync)["kp_long"].hi == DIMENSIONLESS_MAX
    assert field_limits(Tractor)["rear_axle_x_m"].lo == -1e4


def test_a_problem_only_the_override_causes_points_at_the_override():
    """The file alone is valid: a cross-field problem the override causes is reported at <--set>, not at the
    packaged file's line."""
    problems = _problems(["cart.interior_depth_m=0.5"])
    assert {(p.file, p.line, p.col) for p in problems} == {(SET_FILE, 1, 23)}
    assert {p.path for p in problems} == {"grain.initial_fill_m", "controller.target_fill_m"}
    assert all(p.message.endswith("(after --set cart.interior_depth_m=0.5)") for p in problems)
    [problem] = _problems(["timing.latency_frames=2", "controller.target_fill_m=2.5"])
    assert (problem.file, problem.line, problem.path) == (SET_FILE, 2, "controller.target_fill_m")
    # a problem the file has on its own stays at the file's line
    with pytest.raises(ScenarioError) as info:
        load_scenario_text("format_version: 1\nduration_s: -1\n", "f.yaml", ["seed=3"])
    assert [(p.file, p.line) for p in info.value.problems] == [("f.yaml", 2)]


def test_sizes_the_machine_cannot_hold_are_refused_at_their_key():
    [problem] = _problems(["grain.cell_m=0.000001"])
    assert (problem.path, problem.file) == ("grain.cell_m", SET_FILE)
    assert "6,000,000 x 3,000,000 cells; at most 4,194,304 cells fit" in problem.message
    [problem] = _problems(["controller.grid_cell_m=0.0001"])
    assert problem.path == "controller.grid_cell_m" and "60,000 x 30,000 cells" in problem.message
    [problem] = _problems(["grain.cell_m=0.07"])          # a traceback inside validate, before
    assert problem.path == "grain.cell_m" and "does not divide the cart interior length 6 m" in problem.message


def test_control_characters_are_refused_in_files_and_overrides(tmp_path, capsys):
    nul = tmp_path / "nul.yaml"
    nul.write_bytes(b"format_version: 1\nname: a\x00b\n")
    assert main(["validate", str(nul)]) == 2
    err = capsys.readouterr().err
    assert f"{nul}:2:8: <root>: control character U+0000 in the text" in err and "Traceback" not in err
    assert main(["validate", "default", "--set", "name=a\x1bb"]) == 2          # a raw escape typed into --set
    err = capsys.readouterr().err
    assert "<--set>:1:7: name: control character U+001B in the text" in err and "Traceback" not in err
    [problem] = _problems(['description="bell\\a"'])        # an escape sequence that YAML decodes
    assert problem.path == "description" and "control character U+0007 at position 4" in problem.message
    with pytest.raises(ScenarioError) as info:
        load_scenario_text('format_version: 1\ncontroller:\n  strategy_options: {"a\\eb": 1}\n')
    assert "\x1b" not in str(info.value)          # nothing of it reaches the terminal raw
    assert "controller.strategy_options.a\\x1bb: key 'a\\x1bb' holds the control character U+001B" in str(info.value)


def test_deep_nesting_is_refused_before_it_exhausts_the_stack(tmp_path, capsys):
    deep = tmp_path / "deep.yaml"
    deep.write_text("format_version: 1\nsensor: " + "[" * 20_000 + "]" * 20_000 + "\n")
    assert main(["validate", str(deep)]) == 2
    err = capsys.readouterr().err
    assert f"the document nests deeper than {MAX_DEPTH} levels" in err and "Traceback" not in err
    block = "format_version: 1\n" + "".join(f"{'  ' * i}k{i}:\n" for i in range(40)) + "  " * 40 + "v: 1\n"
    with pytest.raises(ScenarioError, match=f"nests deeper than {MAX_DEPTH}"):
        load_scenario_text(block)
    nested: list = []
    for _ in range(20_000):
        nested = [nested]
    with pytest.raises(ScenarioError, match=f"nests deeper than {MAX_DEPTH} levels"):   # the API's overrides=
        load_scenario_text("format_version: 1\n", extra={"controller.strategy_options": {"x": nested}})


def test_integers_beyond_64_bits_are_refused_at_their_key():
    with pytest.raises(ScenarioError, match=r"controller.model_options.n: 100000000000000000000 does not fit a "
                                            r"64-bit integer"):
        load_scenario_text("format_version: 1\ncontroller:\n  model_options: {n: 100000000000000000000}\n")
    assert math.isfinite(float(2**63 - 1))
