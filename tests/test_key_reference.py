"""docs/keys.md is the key reference generated from the records (cosim.scenario.keys): current, every top-level
key under one topic, the first keys real ones, defaults those of the enclosing record."""
from __future__ import annotations

from cosim.scenario.config import Scenario
from cosim.scenario.jsonschema import scenario_json_schema
from cosim.scenario.keys import FIRST, KEYS_PATH, TOPICS, key_reference, key_rows


def test_the_committed_page_is_current():
    assert KEYS_PATH.read_text(encoding="utf-8") == key_reference(), (
        "docs/keys.md is stale: python -m cosim.scenario.keys docs/keys.md")


def test_every_top_level_key_is_under_one_topic():
    tops = [k for keys in TOPICS.values() for k in keys]
    assert sorted(tops) == sorted(Scenario.model_fields)


def test_the_first_keys_exist_and_defaults_come_from_the_enclosing_record():
    schema = scenario_json_schema()
    rows = {r[0]: r for r in key_rows(schema, schema)}
    assert set(FIRST) <= set(rows)
    mount = Scenario(format_version=1).sensor.mount
    assert rows["sensor.mount.xyz_m"][2] == str(list(mount.xyz_m)).replace("(", "[").replace(")", "]")
    assert rows["format_version"][2] == "required"
    assert rows["timing.schedule"][2] == '"pipelined"' and '"overlapped"' in rows["timing.schedule"][1]
