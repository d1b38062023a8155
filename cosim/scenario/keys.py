"""The scenario key reference (docs/keys.md), generated from the JSON Schema of the records: every key by topic,
with its default and description, the few keys a typical scenario sets first. ``tests/test_key_reference.py``
fails while the committed page differs from :func:`key_reference`.

    python -m cosim.scenario.keys docs/keys.md      # write it
"""
from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Iterator

from cosim.scenario.jsonschema import scenario_json_schema

__all__ = ["FIRST", "TOPICS", "KEYS_PATH", "key_rows", "key_reference"]

#: the committed page
KEYS_PATH = Path(__file__).resolve().parents[2] / "docs" / "keys.md"
#: the keys a typical scenario sets, in the order a reader meets them
FIRST = ("name", "description", "duration_s", "seed", "feedback", "renderer", "crop.name", "grain.initial_fill_m",
         "controller.target_fill_m", "controller.strategy", "sensor.mount.xyz_m", "sensor.mount.rpy_deg",
         "timing.latency_frames", "atmosphere.visibility_m", "terrain.roughness_rms_m")
#: topic -> the top-level keys under it (every top-level key is in one topic)
TOPICS: dict[str, tuple[str, ...]] = {
    "The run": ("format_version", "name", "description", "seed", "duration_s", "feedback", "renderer", "viewer",
                "timing", "integrator", "outputs", "outcome", "plugin_dir"),
    "Machines and crop": ("crop", "combine", "tractor", "cart", "auger", "machine_sync", "vehicles", "grain"),
    "The offloading controller": ("controller",),
    "Sensors, rendering and perception": ("sensor", "sensors", "render", "perception"),
    "Field conditions": ("terrain", "atmosphere", "field"),
}


def _deref(schema: dict, node: dict) -> dict:
    """``node`` with a ``$ref`` (or a one-element ``allOf`` of one) replaced by its definition."""
    ref = node.get("$ref") or (node["allOf"][0].get("$ref") if len(node.get("allOf", ())) == 1 else None)
    return schema["$defs"][ref.rsplit("/", 1)[-1]] if ref else node


def _record(schema: dict, node: dict) -> tuple[dict | None, bool]:
    """(the record ``node`` holds, whether it may be null instead), or (None, False) for a plain value."""
    target = _deref(schema, node)
    if "properties" in target:
        return target, False
    members = [_deref(schema, m) for m in target.get("anyOf", ())]
    records = [m for m in members if "properties" in m]
    if len(records) == 1 and len(members) == 2 and any(m.get("type") == "null" for m in members):
        return records[0], True
    return None, False


def _type(schema: dict, node: dict) -> str:
    node = _deref(schema, node)
    if "enum" in node:
        return " / ".join(json.dumps(v) for v in node["enum"])
    if "const" in node:
        return json.dumps(node["const"])
    if "anyOf" in node:
        return " or ".join(_type(schema, m) for m in node["anyOf"])
    if node.get("type") == "array":
        return f"list of {_type(schema, node['items'])}" if "items" in node else "list"
    return str(node.get("type", "object"))


def key_rows(schema: dict, node: dict, prefix: str = "",
             defaults: dict | None = None) -> Iterator[tuple[str, str, str, str]]:
    """(dotted key, type, default as JSON, description) of every leaf key under record ``node``, in order;
    ``defaults``: the enclosing key's default record, which wins over the record type's own defaults (the
    LiDAR's mount is not ``Mount()``)."""
    required = set(node.get("required", ()))
    for key, sub in node.get("properties", {}).items():
        path = f"{prefix}.{key}" if prefix else key
        default = defaults[key] if isinstance(defaults, dict) and key in defaults else sub.get("default")
        shown = "required" if key in required and "default" not in sub else json.dumps(default)
        record, nullable = _record(schema, sub)
        if record is not None:
            if nullable:
                yield path, "record or null", shown, sub.get("description", "")
            yield from key_rows(schema, record, path, default if isinstance(default, dict) else None)
            continue
        items = sub.get("patternProperties")
        kinds = next(iter(items.values()), {}).get("oneOf", ()) if isinstance(items, dict) else ()
        yield path, _type(schema, sub) if not kinds else "mapping", shown, sub.get("description", "")
        for kind in kinds:
            target = _deref(schema, kind)
            name = target["properties"]["kind"].get("const", target["properties"]["kind"].get("default"))
            yield from key_rows(schema, target, f"{path}.<name> (kind {name})")


def _cell(text: str) -> str:
    return " ".join(str(text).split()).replace("|", "\\|")


def _default(shown: str) -> str:
    return shown if shown == "required" else f"`{_cell(shown)}`"


def key_reference(schema: dict | None = None) -> str:
    """The Markdown of docs/keys.md."""
    schema = schema or scenario_json_schema()
    rows = {r[0]: r for r in key_rows(schema, schema)}
    lines = ["# Scenario keys", "",
             "Every key of a scenario file, by topic, with its default and what it means (units in the key's "
             "suffix). Generated from the records (`python -m cosim.scenario.keys docs/keys.md`); the JSON Schema "
             "for editors is `cosim/schema/scenario.schema.json`. A scenario states only what differs from the "
             "defaults, and may start from another with `extends: NAME_OR_PATH` (docs/usage.md).", "",
             "## The keys a typical scenario sets", "", "| key | default | meaning |", "|---|---|---|"]
    lines += [f"| `{k}` | {_default(rows[k][2])} | {_cell(rows[k][3])} |" for k in FIRST]
    for topic, tops in TOPICS.items():
        lines += ["", f"## {topic}", "", "| key | type | default | meaning |", "|---|---|---|---|"]
        lines += [f"| `{k}` | {_cell(t)} | {_default(d)} | {_cell(desc)} |" for k, t, d, desc in rows.values()
                  if k.split(".")[0] in tops]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":  # python -m cosim.scenario.keys [PATH]
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else KEYS_PATH
    out.write_text(key_reference(), encoding="utf-8")
    print(out)
