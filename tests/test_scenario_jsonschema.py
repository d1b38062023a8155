"""The exported JSON Schema: the committed copy is current, and it accepts and rejects what the loader does."""
from __future__ import annotations

import json
import re

import pytest
import yaml

from cosim.scenario.jsonschema import SCHEMA_DIALECT, SCHEMA_PATH, scenario_json_schema, schema_text, write_json_schema
from cosim.scenario.loader import packaged_scenarios
from cosim.scenario.yamlmarks import Loader as _Loader


def test_committed_schema_is_current():
    assert SCHEMA_PATH.read_text(encoding="utf-8") == schema_text(), \
        "cosim/schema/scenario.schema.json is stale: run `python -m cosim.scenario.jsonschema`"


def test_schema_header_and_shape():
    schema = scenario_json_schema()
    assert schema["$schema"] == SCHEMA_DIALECT == "https://json-schema.org/draft/2020-12/schema"
    assert schema["title"] == "graincosim scenario" and "format_version" in schema["description"]
    assert schema["required"] == ["format_version"]
    assert schema["additionalProperties"] is False
    assert schema["properties"]["format_version"]["const"] == 1
    assert schema["$defs"]["Timing"]["additionalProperties"] is False
    strategy = schema["$defs"]["Controller"]["properties"]["strategy"]
    assert strategy["default"] == "front_to_back" and strategy["type"] == "string"
    assert re.fullmatch(strategy["pattern"], "my_pkg.fill:middle_out") and not re.fullmatch(strategy["pattern"], "a b")


def test_write_json_schema(tmp_path):
    out = write_json_schema(tmp_path / "sub" / "s.json")
    assert json.loads(out.read_text(encoding="utf-8")) == scenario_json_schema()


def test_packaged_scenarios_validate_against_the_schema():
    jsonschema = pytest.importorskip("jsonschema")
    validator = jsonschema.Draft202012Validator(scenario_json_schema())
    validator.check_schema(validator.schema)
    for name, path in packaged_scenarios().items():
        data = yaml.load(path.read_text(encoding="utf-8"), Loader=_Loader)
        assert list(validator.iter_errors(data)) == [], name


@pytest.mark.parametrize("doc, path, fragment", [
    ({"format_version": 1, "timing": {"sensor_rate_hz": 10}}, ["timing"], "'sensor_rate_hz' was unexpected"),
    ({"format_version": 2}, ["format_version"], "1 was expected"),
    ({"format_version": 1, "controller": {"estimator": "random"}}, ["controller", "estimator"], "is not one of"),
    ({"format_version": 1, "controller": {"strategy": "my mod"}}, ["controller", "strategy"], "does not match"),
    ({"format_version": 1, "duration_s": "10"}, ["duration_s"], "is not of type 'number'"),
    ({"format_version": 1, "sensor": {"mount": {"xyz_m": [1, 2]}}}, ["sensor", "mount", "xyz_m"], "too short"),
    ({"duration_s": 10.0}, [], "'format_version' is a required property"),
])
def test_schema_rejects_bad_documents(doc, path, fragment):
    jsonschema = pytest.importorskip("jsonschema")
    errors = list(jsonschema.Draft202012Validator(scenario_json_schema()).iter_errors(doc))
    assert [(list(e.absolute_path), fragment in e.message) for e in errors] == [(path, True)], errors


def _properties(schema: dict):
    """(where, property schema) of every property of the schema and its definitions."""
    for name, body in [("<root>", schema), *schema["$defs"].items()]:
        for key, prop in body.get("properties", {}).items():
            yield f"{name}.{key}", prop


def test_every_property_has_a_description():
    """Editors explain each key from the schema: every property carries a description (a field's docstring)."""
    props = list(_properties(scenario_json_schema()))
    assert len(props) > 150
    missing = [where for where, prop in props if not str(prop.get("description", "")).strip()]
    assert missing == [], f"{len(missing)} of {len(props)} properties have no description: {missing}"


def test_every_numeric_property_is_bounded():
    """Every number a scenario holds has a lower and an upper bound in the schema (its own, or its unit's)."""
    def numeric(prop):
        branches = prop.get("prefixItems") or [b for b in prop.get("anyOf", []) if b.get("type") != "null"] or [prop]
        return [b for b in branches if b.get("type") in ("number", "integer") and not {"const", "enum"} & set(b)]

    unbounded = [where for where, prop in _properties(scenario_json_schema()) for b in numeric(prop)
                 if not (("minimum" in b or "exclusiveMinimum" in b) and ("maximum" in b or "exclusiveMaximum" in b))]
    assert unbounded == []
    timing = scenario_json_schema()["$defs"]["Timing"]["properties"]
    assert timing["sensor_period_s"]["maximum"] == 1.0 and timing["handoff_timeout_s"]["maximum"] == 1e5


def test_schema_describes_extends():
    jsonschema = pytest.importorskip("jsonschema")
    schema = scenario_json_schema()
    assert "packaged scenario" in schema["properties"]["extends"]["description"]
    assert list(jsonschema.Draft202012Validator(schema).iter_errors({"format_version": 1, "extends": "default"})) == []
