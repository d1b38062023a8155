"""JSON Schema (draft 2020-12) of scenario files, so that editors can complete and check them.

The committed copy lives at ``cosim/schema/scenario.schema.json``; regenerate it after changing any record in
``cosim/scenario/config`` with ``python -m cosim.scenario.jsonschema`` (a test fails while the committed copy is stale). To use it
in an editor with the YAML language server, start a scenario file with::

    # yaml-language-server: $schema=<path to>/cosim/schema/scenario.schema.json

The schema checks keys, types, enums and ranges field by field (the ranges include the limits of each key's unit,
cosim.scenario.config.limits), and describes every key (a field's docstring); cross-field rules (integer rate
ratios, codec alpha/beta, ...) are checked only by the loader (``cosim.scenario.loader``). ``extends`` (the
loader's, cosim.scenario.extends) is a key of the file, not of the record, and is added here.
"""
from __future__ import annotations

import json
import os
import sys
from pathlib import Path

from .config import Scenario
from .extends import EXTENDS_DESCRIPTION, EXTENDS_KEY

__all__ = ["SCHEMA_PATH", "SCHEMA_DIALECT", "scenario_json_schema", "schema_text", "write_json_schema"]

#: where the generated schema is committed
SCHEMA_PATH = Path(__file__).resolve().parent.parent / "schema" / "scenario.schema.json"
SCHEMA_DIALECT = "https://json-schema.org/draft/2020-12/schema"


def scenario_json_schema() -> dict:
    """The JSON Schema of a scenario file (validation mode: what a file may contain, defaults shown)."""
    body = Scenario.model_json_schema(mode="validation")
    head = {
        "$schema": SCHEMA_DIALECT,
        "title": "graincosim scenario",
        "description": (
            "A co-simulation scenario for perception-in-the-loop grain offloading (combine -> tractor-pulled "
            "grain cart, simulated LiDAR). Only format_version is required; every other key overrides a default. "
            "Units are in the key names (_m, _s, _deg, ...); relative paths are resolved against the scenario "
            "file's directory. `extends` starts from another scenario."
        ),
    }
    body.pop("title", None)
    body.pop("description", None)
    body["properties"][EXTENDS_KEY] = {"type": "string", "minLength": 1, "title": "Extends",
                                       "description": EXTENDS_DESCRIPTION}
    return {**head, **body}


def schema_text() -> str:
    """The schema as committed: 2-space indented JSON, keys in a stable order, trailing newline."""
    return json.dumps(scenario_json_schema(), indent=2, sort_keys=True) + "\n"


def write_json_schema(path: str | os.PathLike = SCHEMA_PATH) -> Path:
    """Write the schema to ``path`` (default: the committed copy); returns the path written."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(schema_text(), encoding="utf-8")
    return path


if __name__ == "__main__":  # python -m cosim.scenario.jsonschema [PATH]
    print(write_json_schema(*sys.argv[1:2]))
