"""Scenario loading: YAML with line/col marks -> overrides -> path resolution -> strict validation.

A scenario is validated whole before anything starts (docs/architecture.md). Every problem found (YAML syntax,
duplicate keys, ``--set`` overrides, missing files, every pydantic error) is collected and raised once as a
:class:`cosim.errors.ScenarioError`, each problem as ``file:line:col: dotted.path: message`` (1-based).

YAML scalars follow the YAML 1.2 core schema: ``1e-8`` is a number, ``on``/``yes`` are strings, only
``true``/``false`` are booleans, dates stay strings. Values are then validated by ``Scenario.model_validate_json``
(strict JSON mode: ``"10"`` is not a float, ``1`` is not a bool).

Overrides, applied in order after the file: ``--set a.b.c=value`` (value parsed as YAML, e.g. ``[1, 2, 3]``; a
mapping value merges key by key, anything else replaces), reported as file ``<--set>`` (line = position of the
override, col = column inside it); then ``extra`` (from CLI options such as ``--renderer``: dotted keys, plain
values, ``None`` skipped), reported as file ``<options>``. Relative paths (every field typed ``Path``) are resolved against the scenario file's directory,
or the working directory for values given on the command line.
"""
from __future__ import annotations

import difflib
import json
import os
import re
import types
import typing
from collections.abc import Mapping, Sequence
from pathlib import Path

import yaml
from pydantic import BaseModel, ValidationError

from cosim.errors import Problem, ScenarioError

from .config import FORMAT_VERSION, Scenario
from .plausibility import implausible
from .trust import CHECKS, PLUGIN_POINTS, check_plugin_refs, options_key
from .yamlmarks import Doc as _Doc
from .yamlmarks import Dumper as _Dumper
from .yamlmarks import Loc
from .yamlmarks import Mark as _Mark
from .yamlmarks import dotted as _dotted
from .yamlmarks import parse as _parse
from .yamlmarks import show as _show

__all__ = [
    "SCENARIO_DIR", "SET_FILE", "OPTIONS_FILE", "load_scenario", "load_scenario_text", "packaged_scenarios",
    "resolve_scenario_arg", "dump_resolved", "path_fields", "MAX_SCENARIO_BYTES", "describe_packaged",
]

#: directory of the scenarios shipped with the package
SCENARIO_DIR = Path(__file__).resolve().parent.parent / "scenarios"
#: pseudo file name of problems in ``--set`` overrides
SET_FILE = "<--set>"
#: pseudo file name of problems in options passed as ``extra``
OPTIONS_FILE = "<options>"

#: largest scenario file (or text) read, bytes: a scenario is a few KiB; a larger one is refused before parsing
MAX_SCENARIO_BYTES = 1 << 20

_KEY = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")

def _model_of(annotation) -> type[BaseModel] | None:
    """The record class behind an annotation (``Model``, ``Model | None``), else None."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    if typing.get_origin(annotation) in (typing.Union, types.UnionType):
        found = [m for m in map(_model_of, typing.get_args(annotation)) if m is not None]
        return found[0] if len(found) == 1 else None
    return None


def _is_path(annotation) -> bool:
    if annotation is Path:
        return True
    return typing.get_origin(annotation) in (typing.Union, types.UnionType) and Path in typing.get_args(annotation)


def path_fields(model: type[BaseModel] = Scenario, prefix: Loc = ()) -> list[Loc]:
    """Every field typed ``Path`` (or ``Path | None``) under ``model``, as key tuples, e.g. ``('cart', 'mesh_file')``."""
    out: list[Loc] = []
    for name, info in model.model_fields.items():
        sub = _model_of(info.annotation)
        if sub is not None:
            out += path_fields(sub, prefix + (name,))
        elif _is_path(info.annotation):
            out.append(prefix + (name,))
    return out


def _entry_models(annotation) -> list[type[BaseModel]]:
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


def _doc_path_fields(data) -> list[Loc]:
    """:func:`path_fields` plus the ``Path`` fields inside free-keyed mappings of records, for the keys ``data``
    (the scenario document) has there (e.g. ``('sensors', 'mast', 'pattern', 'csv_file')``)."""
    out = path_fields()
    for name, info in Scenario.model_fields.items():
        models = _entry_models(info.annotation)
        entries = data.get(name) if isinstance(data, dict) else None
        if not models or not isinstance(entries, dict):
            continue
        for key in entries:
            out += sorted({loc for m in models for loc in path_fields(m, (name, key))})
    return out


def _model_at(loc: Loc) -> type[BaseModel] | None:
    model: type[BaseModel] | None = Scenario
    for part in loc:
        if model is None or part not in model.model_fields:
            return None
        model = _model_of(model.model_fields[part].annotation)
    return model


def _unknown_key(key: str, model: type[BaseModel] | None, where: str = "") -> str:
    message = f"unknown key '{key}'" + (f" in '{where}'" if where else "")
    if model is not None:
        close = difflib.get_close_matches(key, list(model.model_fields), n=1)
        message += f" (did you mean '{close[0]}'?)" if close else f"; allowed: {', '.join(model.model_fields)}"
    return message


def _tuple_len(loc: Loc) -> int | None:
    """Length of the fixed-length tuple field at ``loc``, None when it is not one."""
    model = _model_at(loc[:-1]) if loc else None
    if model is None or loc[-1] not in model.model_fields:
        return None
    ann = model.model_fields[loc[-1]].annotation
    args = typing.get_args(ann)
    return len(args) if typing.get_origin(ann) is tuple and Ellipsis not in args else None


def _free_mapping(loc: Loc) -> bool:
    """Whether ``loc`` names a field whose keys are free: a mapping (a plug-in's ``*_options``, an FMU's
    ``parameters`` or variable mapping, the named sensors of ``sensors``), any key, checked later by what reads
    it."""
    model = _model_at(loc[:-1]) if loc else None
    field = model.model_fields.get(loc[-1]) if model is not None else None
    return field is not None and typing.get_origin(field.annotation) is dict


def _check_override_path(loc: Loc) -> str | None:
    """Why ``loc`` names no field of the scenario, or None when it does."""
    for i, part in enumerate(loc):
        if _free_mapping(loc[:i]):
            return None
        model = _model_at(loc[:i])
        if model is None:
            return f"'{_dotted(loc[:i])}' is a value, not a section: it has no key '{part}'"
        if part not in model.model_fields:
            return _unknown_key(part, model, _dotted(loc[:i]))
    return None


# -------------------------------------------------------------------------------------------- overrides
def _assign(doc: _Doc, loc: Loc, value, vdoc: _Doc, rel: Loc, key_mark: _Mark) -> str | None:
    """Put ``value`` at ``loc`` (mappings merge key by key); copy its marks from ``vdoc`` at ``rel``."""
    parent = doc.data
    for i, part in enumerate(loc[:-1]):
        if part not in parent:
            parent[part] = {}
            doc.keys[loc[: i + 1]] = doc.values[loc[: i + 1]] = key_mark
        parent = parent[part]
        if not isinstance(parent, dict):
            return f"cannot set a key inside '{_dotted(loc[: i + 1])}': it is not a mapping in the scenario"
    old = parent.get(loc[-1])
    if isinstance(old, dict) and isinstance(value, dict):
        for k, v in value.items():
            err = _assign(doc, loc + (k,), v, vdoc, rel + (k,), vdoc.keys.get(rel + (k,), key_mark))
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


def _apply_set(doc: _Doc, text: str, index: int) -> None:
    head = _Mark(SET_FILE, index, 1)
    key, sep, raw = text.partition("=")
    parts = tuple(key.strip().split("."))
    if not sep or not all(_KEY.match(p) for p in parts):
        doc.problem(head, (), f"malformed override {text!r}: expected PATH=VALUE, e.g. timing.sensor_period_s=0.05")
        return
    reason = _check_override_path(parts)
    if reason:
        doc.problem(head, parts, reason)
        return
    vdoc = _parse(raw, SET_FILE, index, len(key) + 1)
    if vdoc.problems:
        doc.problems += [Problem(p.file, p.line, p.col, _dotted(parts), p.message) for p in vdoc.problems]
        return
    err = _assign(doc, parts, vdoc.data, vdoc, (), head)
    if err:
        doc.problem(head, parts, err)


def _plain(value):
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return str(value) if isinstance(value, os.PathLike) else value


def _apply_extra(doc: _Doc, extra: Mapping) -> None:
    mark = _Mark(OPTIONS_FILE, 0, 0)
    for key, value in extra.items():
        if value is None:
            continue
        parts = tuple(str(key).split("."))
        value = _plain(value)
        reason = _check_override_path(parts)
        if reason is None and not _jsonable(value):
            reason = f"option value {value!r} is not a plain YAML value"
        if reason is None:
            marks = {loc: mark for loc in _locs(value)}
            vdoc = _Doc(data=value, keys=marks, values=dict(marks))
            reason = _assign(doc, parts, value, vdoc, (), mark)
        if reason:
            doc.problem(mark, parts, reason)


def _locs(value, loc: Loc = ()) -> list[Loc]:
    """Every path inside ``value`` (``()`` included)."""
    items = value.items() if isinstance(value, dict) else enumerate(value) if isinstance(value, list) else ()
    return [loc] + [sub for k, v in items for sub in _locs(v, loc + (k,))]


def _jsonable(value) -> bool:
    if isinstance(value, dict):
        return all(_jsonable(v) for v in value.values())
    if isinstance(value, list):
        return all(_jsonable(v) for v in value)
    return value is None or isinstance(value, (str, int, float, bool))


# ------------------------------------------------------------------------------------------------ paths
def _resolve_paths(doc: _Doc, base_dir: Path) -> None:
    for loc in _doc_path_fields(doc.data):
        parent = doc.data
        for part in loc[:-1]:
            parent = parent.get(part) if isinstance(parent, dict) else None
        if not isinstance(parent, dict) or not isinstance(parent.get(loc[-1]), str):
            continue
        mark = doc.values.get(loc, doc.values[()])
        base = Path.cwd() if mark.file in (SET_FILE, OPTIONS_FILE) else base_dir
        path = (base / Path(parent[loc[-1]]).expanduser()).resolve()
        parent[loc[-1]] = str(path)
        if not path.is_file():
            what = "is not a file" if path.exists() else "does not exist"
            doc.problem(mark, loc, f"file {str(path)!r} {what} (relative paths are resolved against {str(base)!r})")


def _set_plugin_dir(doc: _Doc, base_dir: Path) -> None:
    """``plugin_dir``: the scenario's folder unless given (a relative one is resolved against it)."""
    given = doc.data.get("plugin_dir")
    if isinstance(given, str):
        mark = doc.values.get(("plugin_dir",), doc.values[()])
        base = Path.cwd() if mark.file in (SET_FILE, OPTIONS_FILE) else base_dir
        doc.data["plugin_dir"] = str((base / Path(given).expanduser()).resolve()) if given else ""
    elif "plugin_dir" not in doc.data:
        doc.data["plugin_dir"] = str(base_dir)


def _check_external(doc: _Doc, scenario: Scenario | None, allow_plugins: bool) -> None:
    """Import and check every plug-in the document names (its raw values, so that they are checked even when
    other keys are invalid; keys already reported are skipped), then, on a valid scenario, every other external
    model (cosim.scenario.trust.CHECKS)."""
    reported = {p.path for p in doc.problems}
    refs = []
    for loc, group in PLUGIN_POINTS:
        okey = options_key(loc)
        options = _at(doc.data, okey) if _existing(doc.data, okey) == okey else {}
        if not isinstance(options, dict) or _dotted(okey) in reported:
            options = {}                    # a bad mapping is the validation's to report
        if _existing(doc.data, loc) == loc:
            ref = _at(doc.data, loc)
        elif options:                       # options for the default plug-in
            ref = _model_at(loc[:-1]).model_fields[loc[-1]].default
        else:
            continue
        if isinstance(ref, str) and _dotted(loc) not in reported:
            refs.append((loc, group, ref, options))
    plugin_dir = doc.data.get("plugin_dir") if isinstance(doc.data.get("plugin_dir"), str) else ""
    _, issues = check_plugin_refs(refs, plugin_dir, allow_plugins=allow_plugins)
    for check in CHECKS if scenario is not None else ():
        issues += check(scenario, allow_plugins=allow_plugins, versions=False)[1]
    for issue in issues:
        found = _existing(doc.data, issue.loc)
        mark = doc.values.get(found, doc.values[()])
        doc.problem(mark, issue.loc, issue.message)


# ------------------------------------------------------------------------------------------- validation
def _existing(data, loc: Loc) -> Loc:
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


def _clean_loc(data, loc: Loc) -> Loc:
    """``loc`` without pydantic's union-member tags (e.g. ``function-after[...]``): keep the parts that exist in
    ``data``, identifier-like names and the last part (a missing or unknown key)."""
    out: Loc = ()
    node = data
    for i, part in enumerate(loc):
        if isinstance(node, (dict, list)) and _existing(node, (part,)):
            node = node[part]
        elif isinstance(node, dict) and part == node.get("kind"):
            continue                                  # the tag of a union picked by kind (sensors.<name>)
        elif isinstance(part, str) and not _KEY.match(part) and i < len(loc) - 1:
            continue
        else:
            node = None
        out += (part,)
    return out


def _at(data, loc: Loc):
    for part in loc:
        data = data[part]
    return data


def _error_problem(err: dict, doc: _Doc) -> Problem:
    kind, msg = err["type"], err["msg"]
    loc = _clean_loc(doc.data, tuple(err["loc"]))
    found = _existing(doc.data, loc)
    node = _at(doc.data, found)
    root = doc.values[()]
    if kind == "extra_forbidden":
        mark, msg = doc.keys.get(found, root), _unknown_key(str(loc[-1]), _model_at(loc[:-1]))
    elif kind == "missing":
        mark = doc.keys.get(found, root) if isinstance(node, dict) else doc.values.get(found, root)
        if isinstance(loc[-1], int):  # a short list for a fixed-length tuple: report once, at the list
            loc, size = found, _tuple_len(found)
            msg = f"expected {size or 'more'} items, got {len(node)}"
        else:
            msg = f"missing required key '{loc[-1]}'"
        if loc == ("format_version",):
            msg += f"; this version of graincosim reads format_version: {FORMAT_VERSION}"
    elif msg.startswith(("Value error, ", "Assertion failed, ")):
        # a model validator names its section (report the section's key), a field validator its value
        mark = doc.keys.get(found, root) if isinstance(node, dict) else doc.values.get(found, root)
        msg = msg.split(", ", 1)[1]
    else:
        mark = doc.values.get(found, root)
        msg = msg.replace("an object", "a mapping").replace("a valid dictionary", "a mapping")
        if loc == ("format_version",):
            msg = f"unsupported format_version {_show(err.get('input'))}; this version of graincosim reads " \
                  f"format_version: {FORMAT_VERSION}"
        elif "input" in err and not isinstance(err["input"], dict):
            msg += f", got {_show(err['input'])}"
            if kind == "model_type" and err["input"] is None:
                msg += " (an empty section: remove the key, or give it at least one entry)"
    return Problem(mark.file, mark.line, mark.col, _dotted(loc), msg)


def _finish(doc: _Doc, filename: str) -> None:
    """Raise the collected problems, deduplicated, in file order (the file, then ``--set``, then options)."""
    if not doc.problems:
        return
    rank = {filename: 0, SET_FILE: 1, OPTIONS_FILE: 2}
    unique = sorted(set(doc.problems), key=lambda p: (rank.get(p.file, 3), p.file, p.line, p.col, p.path))
    raise ScenarioError(unique)


def load_scenario_text(
    text: str,
    filename: str = "<string>",
    overrides: Sequence[str] = (),
    *,
    extra: Mapping | None = None,
    base_dir: str | os.PathLike | None = None,
    check_world: bool = False,
    allow_plugins: bool = True,
) -> Scenario:
    """Parse, override, resolve and validate scenario ``text``; raise ScenarioError with every problem.

    Every plug-in the scenario names is imported and checked (cosim.scenario.trust: importing runs its code);
    ``allow_plugins`` False refuses any that is not built in (``--no-plugins``). ``plugin_dir`` (the folder
    plug-in modules are looked for first) defaults to ``base_dir``.

    ``overrides``: ``"PATH=VALUE"`` strings (``--set``); ``extra``: ``{"dotted.path": value}`` from other options,
    entries whose value is None are skipped. ``base_dir``: directory that relative paths in the text are resolved
    against (default: the directory of ``filename`` if it names a file, else the working directory).
    ``check_world``: also refuse an implausible world at frame 0 (cosim.scenario.plausibility; on by default in
    :func:`load_scenario`, which the CLI uses, off here where a text is only parsed and validated). Texts over
    MAX_SCENARIO_BYTES and alias bombs (cosim.scenario.yamlmarks.MAX_VALUES) are refused before validation.
    """
    if isinstance(overrides, str):
        raise TypeError("overrides must be a sequence of 'PATH=VALUE' strings, not one string")
    if len(text) > MAX_SCENARIO_BYTES:
        raise ScenarioError([_too_large(filename, len(text))])
    doc = _parse(text, filename)
    if doc.problems and not doc.values:  # YAML syntax error: nothing to go on
        _finish(doc, filename)
    if not isinstance(doc.data, dict):
        got = "an empty document" if doc.data is None else f"a {type(doc.data).__name__}"
        doc.problem(doc.values[()], (), f"the top level of a scenario must be a mapping, got {got}")
        _finish(doc, filename)
    version = doc.data.get("format_version")
    if isinstance(version, int) and not isinstance(version, bool) and version != FORMAT_VERSION:
        # another format: its keys may mean other things, so checking them against this one only misleads
        mark = doc.values.get(("format_version",), doc.values[()])
        doc.problem(mark, ("format_version",), f"unsupported format_version {version}; this version of graincosim "
                    f"reads format_version: {FORMAT_VERSION} (nothing else was checked)")
        _finish(doc, filename)
    for i, text_i in enumerate(overrides, start=1):
        _apply_set(doc, text_i, i)
    _apply_extra(doc, extra or {})
    if base_dir is None:
        base_dir = Path(filename).parent if Path(filename).is_file() else Path.cwd()
    _resolve_paths(doc, Path(base_dir).resolve())
    _set_plugin_dir(doc, Path(base_dir).resolve())
    try:
        scenario = Scenario.model_validate_json(json.dumps(doc.data))
    except ValidationError as e:
        doc.problems += [_error_problem(err, doc) for err in e.errors(include_url=False)]
        scenario = None
    _check_external(doc, scenario, allow_plugins)
    _finish(doc, filename)
    if check_world:
        _check_world(doc, scenario, filename)
    return scenario


def _too_large(filename: str, size: int) -> Problem:
    return Problem(filename, 1, 1, "", f"the scenario is {size / 2**20:.1f} MiB; scenarios are limited to "
                   f"{MAX_SCENARIO_BYTES / 2**20:g} MiB (put large tables in files, e.g. sensor.pattern.csv_file)")


def _check_world(doc: _Doc, scenario: Scenario, filename: str) -> None:
    """Raise the plausibility problems of the frame-0 world (cosim.scenario.plausibility) at their keys."""
    for loc, message in implausible(scenario):
        found = _existing(doc.data, loc)  # a section's problem at its key, a value's at the value
        marks = doc.keys if isinstance(_at(doc.data, found), dict) and found else doc.values
        doc.problem(marks.get(found, doc.values[()]), loc, message)
    _finish(doc, filename)


def load_scenario(path: str | os.PathLike, overrides: Sequence[str] = (), *, extra: Mapping | None = None,
                  check_world: bool = True, allow_plugins: bool = True) -> Scenario:
    """Load and validate the scenario file ``path``, and check its frame-0 world (see :func:`load_scenario_text`)."""
    try:
        size = os.stat(path).st_size
        if size > MAX_SCENARIO_BYTES:
            raise ScenarioError([_too_large(str(path), size)])
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise ScenarioError([Problem(str(path), 0, 0, "", f"cannot read scenario file: {e}")]) from None
    return load_scenario_text(text, str(path), overrides, extra=extra, base_dir=Path(path).resolve().parent,
                              check_world=check_world, allow_plugins=allow_plugins)


# -------------------------------------------------------------------------------------- packaged, dump
def packaged_scenarios() -> dict[str, Path]:
    """Scenarios shipped with the package, name (file stem) -> path."""
    return {p.stem: p for p in sorted(SCENARIO_DIR.glob("*.yaml"))}


def resolve_scenario_arg(arg: str | os.PathLike) -> Path:
    """A scenario argument as a file: an existing file path, or the name of a packaged scenario ("default")."""
    path = Path(arg)
    if path.is_file():
        return path
    packaged = packaged_scenarios()
    if str(arg) in packaged:
        return packaged[str(arg)]
    close = difflib.get_close_matches(str(arg), list(packaged), n=1, cutoff=0.6)
    hint = f"; did you mean '{close[0]}'?" if close else ""
    raise ScenarioError([Problem(str(arg), 0, 0, "", f"no such scenario file or packaged scenario (packaged: "
                                 f"{', '.join(packaged) or 'none'}; `launch.py list` describes them){hint}")])


def describe_packaged() -> dict[str, str]:
    """Packaged scenario name -> its ``description`` (first sentence, whitespace collapsed; "" when none)."""
    out = {}
    for name, path in packaged_scenarios().items():
        doc = yaml.safe_load(path.read_text()) or {}
        text = " ".join(str(doc.get("description") or "").split())
        out[name] = text.split(". ")[0].rstrip(".") + "." if text else ""
    return out


def dump_resolved(scenario: Scenario) -> str:
    """The fully resolved scenario (every field, defaults included) as YAML; loading it gives an equal Scenario."""
    body = yaml.dump(scenario.model_dump(mode="json"), Dumper=_Dumper, sort_keys=False, allow_unicode=True,
                     default_flow_style=False, width=120)
    return f"# fully resolved scenario '{scenario.name}' (every field, defaults included)\n{body}"

