"""Changing a scenario document before it is validated: ``--set``, options, and partial blocks.

Every way of changing a scenario (a YAML that states one key of a nested block, ``--set a.b.c=value``, the API's
``overrides=``, a sweep's values, a file that ``extends`` another) ends in :func:`assign`: the value goes to its
path, a mapping merges key by key, anything else replaces. :func:`fill_partial` then completes each block the
document states only in part from the block's *own* default (the record default of the field that holds it, e.g.
``sensor.mount``'s mast pose, not the bare ``Mount()`` origin), so that an override changes only what it names.

The documents are :class:`cosim.scenario.yamlmarks.Doc` (plain data with the line/col of every key and value);
problems are reported at the marks of the values that caused them.
"""
from __future__ import annotations

import difflib
import functools
import os
import re
import types
import typing
from collections.abc import Mapping
from pathlib import Path

from pydantic import BaseModel

from cosim.errors import Problem

from .config import Scenario
from .yamlmarks import MAX_DEPTH, Doc, Loc, Mark, dotted, parse

__all__ = ["SET_FILE", "OPTIONS_FILE", "model_of", "model_at", "path_fields", "entry_models", "doc_path_fields", "unknown_key", "tuple_len",
           "check_override_path", "assign", "apply_set", "apply_extra", "fill_partial", "existing", "at", "KEY",
           "locs"]

#: pseudo file name of problems in ``--set`` overrides
SET_FILE = "<--set>"
#: pseudo file name of problems in options passed as ``extra``
OPTIONS_FILE = "<options>"

KEY = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


# ----------------------------------------------------------------------------------------------- model walk
def model_of(annotation) -> type[BaseModel] | None:
    """The record class behind an annotation (``Model``, ``Model | None``), else None."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    if typing.get_origin(annotation) in (typing.Union, types.UnionType):
        found = [m for m in map(model_of, typing.get_args(annotation)) if m is not None]
        return found[0] if len(found) == 1 else None
    return None


def _is_path(annotation) -> bool:
    if annotation is Path:
        return True
    return typing.get_origin(annotation) in (typing.Union, types.UnionType) and Path in typing.get_args(annotation)


@functools.lru_cache(maxsize=None)
def path_fields(model: type[BaseModel] = Scenario, prefix: Loc = ()) -> tuple[Loc, ...]:
    """Every field typed ``Path`` (or ``Path | None``) under ``model``, as key tuples, e.g. ``('cart', 'mesh_file')``."""
    out: list[Loc] = []
    for name, info in model.model_fields.items():
        sub = model_of(info.annotation)
        if sub is not None:
            out += path_fields(sub, prefix + (name,))
        elif _is_path(info.annotation):
            out.append(prefix + (name,))
    return tuple(out)


def entry_models(annotation) -> list[type[BaseModel]]:
    """The records a free-keyed mapping of records holds (``sensors: name -> sensor``, a union picked by
    ``kind``); [] for any other annotation."""
    if typing.get_origin(annotation) is typing.Annotated:
        annotation = typing.get_args(annotation)[0]
    if typing.get_origin(annotation) is not dict:
        return []
    value = typing.get_args(annotation)[1]
    if typing.get_origin(value) is typing.Annotated:
        value = typing.get_args(value)[0]
    members = typing.get_args(value) if typing.get_origin(value) in (typing.Union, types.UnionType) else (value,)
    return [m for m in members if isinstance(m, type) and issubclass(m, BaseModel)]


def doc_path_fields(data) -> list[Loc]:
    """:func:`path_fields` plus the ``Path`` fields inside free-keyed mappings of records, for the keys ``data``
    (the scenario document) has there (e.g. ``('sensors', 'mast', 'pattern', 'csv_file')``)."""
    out = list(path_fields())
    for name, info in Scenario.model_fields.items():
        models = entry_models(info.annotation)
        entries = data.get(name) if isinstance(data, dict) else None
        if not models or not isinstance(entries, dict):
            continue
        for key in entries:
            out += sorted({loc for m in models for loc in path_fields(m, (name, key))})
    return out


def model_at(loc: Loc) -> type[BaseModel] | None:
    """The record class at scenario key ``loc`` (``()``: Scenario), None where ``loc`` names no record."""
    model: type[BaseModel] | None = Scenario
    for part in loc:
        if model is None or part not in model.model_fields:
            return None
        model = model_of(model.model_fields[part].annotation)
    return model


def unknown_key(key: str, model: type[BaseModel] | None, where: str = "") -> str:
    message = f"unknown key '{key}'" + (f" in '{where}'" if where else "")
    if model is not None:
        close = difflib.get_close_matches(key, list(model.model_fields), n=1)
        message += f" (did you mean '{close[0]}'?)" if close else f"; allowed: {', '.join(model.model_fields)}"
    return message


def tuple_len(loc: Loc) -> int | None:
    """Length of the fixed-length tuple field at ``loc``, None when it is not one."""
    model = model_at(loc[:-1]) if loc else None
    if model is None or loc[-1] not in model.model_fields:
        return None
    ann = model.model_fields[loc[-1]].annotation
    args = typing.get_args(ann)
    return len(args) if typing.get_origin(ann) is tuple and Ellipsis not in args else None


def _free_mapping(loc: Loc) -> bool:
    """Whether ``loc`` names a field whose keys are free: a mapping (a plug-in's ``*_options``, an FMU's
    ``parameters`` or variable mapping, the named sensors of ``sensors``), any key, checked later by what reads
    it."""
    model = model_at(loc[:-1]) if loc else None
    field = model.model_fields.get(loc[-1]) if model is not None else None
    return field is not None and typing.get_origin(field.annotation) is dict


def check_override_path(loc: Loc) -> str | None:
    """Why ``loc`` names no field of the scenario, or None when it does."""
    for i, part in enumerate(loc):
        if _free_mapping(loc[:i]):
            return None
        model = model_at(loc[:i])
        if model is None:
            return f"'{dotted(loc[:i])}' is a value, not a section: it has no key '{part}'"
        if part not in model.model_fields:
            return unknown_key(part, model, dotted(loc[:i]))
    return None


# ------------------------------------------------------------------------------------------------ data walk
def existing(data, loc: Loc) -> Loc:
    """The longest prefix of ``loc`` that names a node present in ``data``."""
    node, found = data, ()
    for part in loc:
        if isinstance(node, dict) and isinstance(part, str) and part in node:
            node = node[part]
        elif isinstance(node, list) and isinstance(part, int) and 0 <= part < len(node):
            node = node[part]
        else:
            break
        found += (part,)
    return found


def at(data, loc: Loc):
    for part in loc:
        data = data[part]
    return data


def locs(value, loc: Loc = ()) -> list[Loc]:
    """Every path inside ``value`` (``()`` included)."""
    items = value.items() if isinstance(value, dict) else enumerate(value) if isinstance(value, list) else ()
    return [loc] + [sub for k, v in items for sub in locs(v, loc + (k,))]


# ------------------------------------------------------------------------------------------------ overrides
def assign(doc: Doc, loc: Loc, value, vdoc: Doc, rel: Loc, key_mark: Mark) -> str | None:
    """Put ``value`` at ``loc`` (mappings merge key by key); copy its marks from ``vdoc`` at ``rel``."""
    parent = doc.data
    for i, part in enumerate(loc[:-1]):
        if part not in parent:
            parent[part] = {}
            doc.keys[loc[: i + 1]] = doc.values[loc[: i + 1]] = key_mark
        parent = parent[part]
        if not isinstance(parent, dict):
            return f"cannot set a key inside '{dotted(loc[: i + 1])}': it is not a mapping in the scenario"
    old = parent.get(loc[-1])
    if isinstance(old, dict) and isinstance(value, dict):
        for k, v in value.items():
            err = assign(doc, loc + (k,), v, vdoc, rel + (k,), vdoc.keys.get(rel + (k,), key_mark))
            if err:
                return err
        return None
    for marks in (doc.keys, doc.values):
        for stale in [p for p in marks if p[: len(loc)] == loc]:
            del marks[stale]
    parent[loc[-1]] = value
    doc.keys[loc] = key_mark
    n = len(rel)
    for src, dst in ((vdoc.keys, doc.keys), (vdoc.values, doc.values)):
        dst.update({loc + p[n:]: m for p, m in src.items() if p[:n] == rel and (p != rel or dst is doc.values)})
    return None


def apply_set(doc: Doc, text: str, index: int) -> None:
    """Apply ``--set`` number ``index`` (1-based), ``PATH=VALUE`` with VALUE parsed as YAML."""
    head = Mark(SET_FILE, index, 1)
    key, sep, raw = text.partition("=")
    parts = tuple(key.strip().split("."))
    if not sep or not all(KEY.match(p) for p in parts):
        doc.problem(head, (), f"malformed override {text!r}: expected PATH=VALUE, e.g. timing.sensor_period_s=0.05")
        return
    reason = check_override_path(parts)
    if reason:
        doc.problem(head, parts, reason)
        return
    vdoc = parse(raw, SET_FILE, index, len(key) + 1)
    if vdoc.problems:
        doc.problems += [Problem(p.file, p.line, p.col, dotted(parts), p.message) for p in vdoc.problems]
        return
    err = assign(doc, parts, vdoc.data, vdoc, (), head)
    if err:
        doc.problem(head, parts, err)


class _NotPlain(Exception):
    """A Python value given as an option is not plain YAML data (or nests too deep); the reason is its text."""


def _plain(value, depth: int = 0):
    """``value`` as plain YAML data (mappings with str keys, lists, str, int, float, bool, None; paths as str)."""
    if depth > MAX_DEPTH:
        raise _NotPlain(f"the value nests deeper than {MAX_DEPTH} levels")
    if isinstance(value, Mapping):
        return {str(k): _plain(v, depth + 1) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v, depth + 1) for v in value]
    if isinstance(value, os.PathLike):
        return str(value)
    if value is None or isinstance(value, (str, int, float, bool)):
        return value
    raise _NotPlain(f"option value {value!r} is not a plain YAML value")


def apply_extra(doc: Doc, extra: Mapping) -> None:
    """Apply options given as ``{"dotted.path": value}`` (values None skipped), reported as file ``<options>``."""
    mark = Mark(OPTIONS_FILE, 0, 0)
    for key, value in extra.items():
        if value is None:
            continue
        parts = tuple(str(key).split("."))
        reason = check_override_path(parts)
        if reason is None:
            try:
                value = _plain(value)
            except _NotPlain as e:
                reason = str(e)
        if reason is None:
            marks = {loc: mark for loc in locs(value)}
            vdoc = Doc(data=value, keys=marks, values=dict(marks))
            reason = assign(doc, parts, value, vdoc, (), mark)
        if reason:
            doc.problem(mark, parts, reason)


# ----------------------------------------------------------------------------------------------- partial blocks
@functools.lru_cache(maxsize=None)
def _field_default(model: type[BaseModel], name: str):
    """The default of ``model``'s field ``name`` (records are frozen: one instance serves every call)."""
    return model.model_fields[name].get_default(call_default_factory=True, validated_data={})


def fill_partial(doc: Doc, model: type[BaseModel] = Scenario, loc: Loc = (), default: BaseModel | None = None) -> None:
    """Complete every block the document gives in part from the default of the field that holds it.

    A record field's default may differ from its record's own field defaults (``Sensor.mount`` is a mast pose,
    ``Mount()`` the origin): a block that states some keys gets the others from the field's default, so that
    ``sensor: {mount: {rpy_deg: ...}}`` keeps the mast's position. Keys equal to the record's own defaults are
    left out (nothing changes for them); filled keys are marked at the block's key."""
    node = at(doc.data, loc) if loc else doc.data
    if not isinstance(node, dict):
        return
    for name in model.model_fields:
        if default is not None and name not in node:
            value = getattr(default, name)
            if value != _field_default(model, name):
                plain = default.model_dump(mode="json", include={name})[name]
                node[name] = plain
                mark = doc.keys.get(loc, doc.values.get((), Mark("<defaults>", 0, 0)))
                for sub in locs(plain, loc + (name,)):
                    doc.keys.setdefault(sub, mark)
                    doc.values.setdefault(sub, mark)
            continue
        sub = model_of(model.model_fields[name].annotation)
        if sub is None or not isinstance(node.get(name), dict):
            continue
        base = getattr(default, name) if default is not None else _field_default(model, name)
        if isinstance(base, sub):
            fill_partial(doc, sub, loc + (name,), base)
