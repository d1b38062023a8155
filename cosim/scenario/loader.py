"""Scenario loading: YAML with line/col marks -> bases -> overrides -> partial blocks -> path resolution ->
value checks -> strict validation -> external models -> the frame-0 world.

A scenario is validated whole before anything starts (docs/architecture.md). Every problem found (YAML syntax,
duplicate keys, ``--set`` overrides, missing files, every pydantic error) is collected and raised once as a
:class:`cosim.errors.ScenarioError`, each problem as ``file:line:col: dotted.path: message`` (1-based).

YAML scalars follow the YAML 1.2 core schema: ``1e-8`` is a number, ``on``/``yes`` are strings, only
``true``/``false`` are booleans, dates stay strings. Values are then validated by ``Scenario.model_validate_json``
(strict JSON mode: ``"10"`` is not a float, ``1`` is not a bool).

* ``extends: NAME_OR_PATH`` starts from another scenario (cosim.scenario.extends).
* Overrides, applied in order after the file: ``--set a.b.c=value`` (value parsed as YAML, e.g. ``[1, 2, 3]``; a
  mapping value merges key by key, anything else replaces), reported as file ``<--set>`` (line = position of the
  override, col = column inside it); then ``extra`` (from CLI options such as ``--renderer``, and the API's
  ``overrides=``: dotted keys, plain values, ``None`` skipped), reported as file ``<options>``.
* A block stated in part keeps the rest of its default (cosim.scenario.overrides.fill_partial): an override
  changes only what it names.
* A problem that only the overrides cause (the file alone has none at that key) is reported at the override that
  most likely caused it (the longest common key prefix; the last one on a tie), not at the file's line.
* Relative paths (every field typed ``Path``, and ``plugin_dir``) are resolved against the folder of the file
  that gave the value (a base's values against the base's folder), or the working directory for values given
  on the command line (``--set``, options).
* Every value is checked whatever key holds it (cosim.scenario.values: finite numbers, 64-bit integers, no
  control characters), and every number is bounded by its unit (cosim.scenario.config.limits).
"""
from __future__ import annotations

import json
import os
import reprlib
from collections.abc import Mapping, Sequence
from pathlib import Path

import yaml
from pydantic import ValidationError

from cosim.errors import Problem, ScenarioError

from .config import FORMAT_VERSION, Scenario
from .config.fielddraw import replaced_keys
from .config.limits import LIMIT_ERROR, unit_of
from .extends import apply_extends
from .files import (
    MAX_SCENARIO_BYTES,
    SCENARIO_DIR,
    describe_packaged,
    packaged_scenarios,
    read_scenario,
    resolve_scenario_arg,
    too_large,
)
from .overrides import KEY as _KEY
from .overrides import (
    OPTIONS_FILE,
    SET_FILE,
    apply_extra,
    apply_set,
    at,
    doc_path_fields,
    existing,
    fill_partial,
    model_at,
    path_fields,
    tuple_len,
    unknown_key,
)
from .plausibility import implausible
from .trust import CHECKS, PLUGIN_POINTS, check_plugin_refs, options_key
from .values import value_problems
from .yamlmarks import Doc as _Doc
from .yamlmarks import Dumper as _Dumper
from .yamlmarks import Loc
from .yamlmarks import dotted as _dotted
from .yamlmarks import parse as _parse
from .yamlmarks import show as _show

__all__ = [
    "SCENARIO_DIR", "SET_FILE", "OPTIONS_FILE", "load_scenario", "load_scenario_text", "packaged_scenarios",
    "resolve_scenario_arg", "dump_resolved", "path_fields", "MAX_SCENARIO_BYTES", "describe_packaged",
]

_COMMAND_LINE = (SET_FILE, OPTIONS_FILE)


# ------------------------------------------------------------------------------------------------ paths
def _folder(mark_file: str, folders: Mapping[str, Path], base_dir: Path) -> Path:
    """The folder a relative path given in ``mark_file`` is resolved against."""
    return Path.cwd() if mark_file in _COMMAND_LINE else folders.get(mark_file, base_dir)


def _resolve_paths(doc: _Doc, folders: Mapping[str, Path], base_dir: Path) -> None:
    for loc in doc_path_fields(doc.data):
        parent = doc.data
        for part in loc[:-1]:
            parent = parent.get(part) if isinstance(parent, dict) else None
        if not isinstance(parent, dict) or not isinstance(parent.get(loc[-1]), str):
            continue
        mark = doc.values.get(loc, doc.values[()])
        base = _folder(mark.file, folders, base_dir)
        path = (base / Path(parent[loc[-1]]).expanduser()).resolve()
        parent[loc[-1]] = str(path)
        if not path.is_file():
            what = "is not a file" if path.exists() else "does not exist"
            doc.problem(mark, loc, f"file {str(path)!r} {what} (relative paths are resolved against {str(base)!r})")


def _set_plugin_dir(doc: _Doc, folders: Mapping[str, Path], base_dir: Path) -> None:
    """``plugin_dir``: the scenario's folder unless given (a relative one is resolved against the folder of the
    file that gives it, or the working directory on the command line)."""
    given = doc.data.get("plugin_dir")
    if isinstance(given, str) and given:
        mark = doc.values.get(("plugin_dir",), doc.values[()])
        doc.data["plugin_dir"] = str((_folder(mark.file, folders, base_dir) / Path(given).expanduser()).resolve())
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
        options = at(doc.data, okey) if existing(doc.data, okey) == okey else {}
        if not isinstance(options, dict) or _dotted(okey) in reported:
            options = {}                    # a bad mapping is the validation's to report
        if existing(doc.data, loc) == loc:
            ref = at(doc.data, loc)
        elif options:                       # options for the default plug-in
            ref = model_at(loc[:-1]).model_fields[loc[-1]].default
        else:
            continue
        if isinstance(ref, str) and _dotted(loc) not in reported:
            refs.append((loc, group, ref, options))
    plugin_dir = doc.data.get("plugin_dir") if isinstance(doc.data.get("plugin_dir"), str) else ""
    _, issues = check_plugin_refs(refs, plugin_dir, allow_plugins=allow_plugins)
    for check in CHECKS if scenario is not None else ():
        issues += check(scenario, allow_plugins=allow_plugins, versions=False)[1]
    for issue in issues:
        found = existing(doc.data, issue.loc)
        mark = doc.values.get(found, doc.values[()])
        doc.problem(mark, issue.loc, issue.message)


# ------------------------------------------------------------------------------------------- validation
def _clean_loc(data, loc: Loc) -> Loc:
    """``loc`` without pydantic's union-member tags (e.g. ``function-after[...]``): keep the parts that exist in
    ``data``, identifier-like names and the last part (a missing or unknown key)."""
    out: Loc = ()
    node = data
    for i, part in enumerate(loc):
        if isinstance(node, (dict, list)) and existing(node, (part,)):
            node = node[part]
        elif isinstance(node, dict) and part == node.get("kind"):
            continue                                  # the tag of a union picked by kind (sensors.<name>)
        elif isinstance(part, str) and not _KEY.match(part) and i < len(loc) - 1:
            continue
        else:
            node = None
        out += (part,)
    return out


def _bound_message(err: dict, loc: Loc) -> str | None:
    """A pydantic bound error (``less_than_equal``, ...) with the unit of the key named, None for another error."""
    if err["type"] not in ("greater_than", "greater_than_equal", "less_than", "less_than_equal") or \
            not isinstance(err.get("input"), (int, float)):
        return None
    key = loc[-2] if len(loc) > 1 and isinstance(loc[-1], int) else loc[-1] if loc else ""
    unit = unit_of(str(key))
    u = f" {unit.symbol}" if unit else ""
    return f"{err['msg']}{u}, got {_show(err['input'])}{u}"


def _error_problem(err: dict, doc: _Doc) -> Problem:
    kind, msg = err["type"], err["msg"]
    loc = _clean_loc(doc.data, tuple(err["loc"]))
    found = existing(doc.data, loc)
    node = at(doc.data, found)
    root = doc.values[()]
    if kind == "extra_forbidden":
        mark, msg = doc.keys.get(found, root), unknown_key(str(loc[-1]), model_at(loc[:-1]))
    elif kind == "missing":
        mark = doc.keys.get(found, root) if isinstance(node, dict) else doc.values.get(found, root)
        if isinstance(loc[-1], int):  # a short list for a fixed-length tuple: report once, at the list
            loc, size = found, tuple_len(found)
            msg = f"expected {size or 'more'} items, got {len(node)}"
        else:
            msg = f"missing required key '{loc[-1]}'"
        if loc == ("format_version",):
            msg += f"; this version of graincosim reads format_version: {FORMAT_VERSION}"
    elif msg.startswith(("Value error, ", "Assertion failed, ")):
        # a model validator names its section (report the section's key), a field validator its value
        mark = doc.keys.get(found, root) if isinstance(node, dict) else doc.values.get(found, root)
        msg = msg.split(", ", 1)[1]
    elif kind == LIMIT_ERROR or _bound_message(err, loc) is not None:
        mark = doc.values.get(found, root)
        msg = msg if kind == LIMIT_ERROR else _bound_message(err, loc)
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


def _common(a: str, b: Sequence[str]) -> int:
    """Length of the common key prefix of dotted path ``a`` and key tuple ``b``."""
    n = 0
    for x, y in zip(a.replace("[", ".[").split("."), b):
        if x != y:
            break
        n += 1
    return n


def _attribute(problems: list[Problem], alone: set[str], given: list[tuple[Problem, tuple, str]]) -> list[Problem]:
    """Problems reported in a file at a key where the file alone has none (``alone``: the keys of its own
    problems) were caused by the overrides: report each at the override (``given``: its mark, keys and text)
    with the longest common key prefix (the last one on a tie)."""
    out = []
    for p in problems:
        if p.file in _COMMAND_LINE or p.path in alone:
            out.append(p)
            continue
        mark, _, text = max(reversed(given), key=lambda g: _common(p.path, g[1]))
        out.append(Problem(mark.file, mark.line, mark.col, p.path, f"{p.message} (after {text})"))
    return out


def _overrides_given(overrides: Sequence[str], extra: Mapping) -> list[tuple[Problem, tuple, str]]:
    """(mark, keys, how it was given) of each override: ``--set`` entries, then options."""
    out = []
    for i, text in enumerate(overrides, start=1):
        key, _, raw = text.partition("=")
        out.append((Problem(SET_FILE, i, len(key) + 2, "", ""), tuple(key.strip().split(".")), f"--set {text}"))
    for key, value in extra.items():
        if value is not None:
            out.append((Problem(OPTIONS_FILE, 0, 0, "", ""), tuple(str(key).split(".")),
                        f"option {key}={reprlib.repr(value)}"))
    return out


def _given_value(raw: str):
    try:
        return yaml.safe_load(raw)
    except yaml.YAMLError:
        return None


def _reaches(value, rest: tuple) -> bool:
    """Whether the plain data ``value`` holds the key path ``rest``."""
    for part in rest:
        if not isinstance(value, dict) or part not in value:
            return False
        value = value[part]
    return True


def _show_ranges(ranges: dict) -> str:
    return ", ".join(f"{k} [{v[0]:g}, {v[1]:g}]" if isinstance(v, (list, tuple)) else f"{k} {v}" for k, v in ranges.items())


def _refuse_drawn(doc: _Doc, overrides: Sequence[str], extra: Mapping) -> None:
    """Refuse an override of a key the scenario's seed draws (``field:``): the draw would replace it unseen. The
    problem names the condition and its range, to set instead or to switch off."""
    field = doc.data.get("field") if isinstance(doc.data, dict) else None
    drawn = replaced_keys(field) if isinstance(field, dict) else {}
    if not drawn:
        return
    given = [(loc, _given_value(text.partition("=")[2]), mark) for (mark, loc, _), text
             in zip(_overrides_given(overrides, {}), overrides)]
    given += [(tuple(str(k).split(".")), v, Problem(OPTIONS_FILE, 0, 0, "", "")) for k, v in extra.items()
              if v is not None]
    for loc, value, mark in given:
        for key, (condition, ranges) in drawn.items():
            kloc = tuple(key.split("."))
            if loc[: len(kloc)] == kloc or (kloc[: len(loc)] == loc and _reaches(value, kloc[len(loc):])):
                doc.problem(mark, loc,
                            f"'{key}' is drawn per seed by this scenario's field (field.draw has '{condition}'; "
                            f"its ranges: {_show_ranges(ranges)}), so a value set here would be drawn over: set "
                            f"its range (e.g. --set field.{condition}.{next(iter(ranges))}=[a, b]) or take "
                            f"'{condition}' out of field.draw")
                break


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
    MAX_SCENARIO_BYTES, alias bombs (cosim.scenario.yamlmarks.MAX_VALUES) and documents nested deeper than
    cosim.scenario.yamlmarks.MAX_DEPTH are refused before validation.
    """
    if isinstance(overrides, str):
        raise TypeError("overrides must be a sequence of 'PATH=VALUE' strings, not one string")
    if base_dir is None:
        base_dir = Path(filename).parent if Path(filename).is_file() else Path.cwd()
    base_dir = Path(base_dir).resolve()
    extra = dict(extra or {})
    try:
        return _load(text, filename, overrides, extra, base_dir, check_world, allow_plugins)
    except ScenarioError as e:
        given = _overrides_given(overrides, extra)
        if not given or all(p.file in _COMMAND_LINE for p in e.problems):
            raise
        try:
            _load(text, filename, (), {}, base_dir, check_world, allow_plugins)
            alone: set[str] = set()
        except ScenarioError as own:
            alone = {p.path for p in own.problems}
        raise ScenarioError(sorted(set(_attribute(e.problems, alone, given)), key=lambda p: (
            {filename: 0, SET_FILE: 1, OPTIONS_FILE: 2}.get(p.file, 3), p.file, p.line, p.col, p.path))) from None


def _load(text: str, filename: str, overrides: Sequence[str], extra: Mapping, base_dir: Path, check_world: bool,
          allow_plugins: bool) -> Scenario:
    if len(text) > MAX_SCENARIO_BYTES:
        raise ScenarioError([too_large(filename, len(text))])
    doc = _parse(text, filename)
    if doc.problems and not doc.values:  # YAML syntax error: nothing to go on
        _finish(doc, filename)
    doc, folders = apply_extends(doc, filename, base_dir)
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
        apply_set(doc, text_i, i)
    apply_extra(doc, extra)
    _refuse_drawn(doc, overrides, extra)
    fill_partial(doc)
    _resolve_paths(doc, folders, base_dir)
    _set_plugin_dir(doc, folders, base_dir)
    refused = {_dotted(loc) for loc in value_problems(doc)}
    try:
        scenario = Scenario.model_validate_json(json.dumps(doc.data))
    except ValidationError as e:
        found = [_error_problem(err, doc) for err in e.errors(include_url=False)]
        doc.problems += [p for p in found if p.path not in refused]   # a refused value is reported once
        scenario = None
    _check_external(doc, scenario, allow_plugins)
    _finish(doc, filename)
    if check_world:
        _check_world(doc, scenario, filename)
    return scenario


def _check_world(doc: _Doc, scenario: Scenario, filename: str) -> None:
    """Raise the plausibility problems of the frame-0 world (cosim.scenario.plausibility) at their keys."""
    for loc, message in implausible(scenario):
        found = existing(doc.data, loc)  # a section's problem at its key, a value's at the value
        marks = doc.keys if isinstance(at(doc.data, found), dict) and found else doc.values
        doc.problem(marks.get(found, doc.values[()]), loc, message)
    _finish(doc, filename)


def load_scenario(path: str | os.PathLike, overrides: Sequence[str] = (), *, extra: Mapping | None = None,
                  check_world: bool = True, allow_plugins: bool = True) -> Scenario:
    """Load and validate the scenario file ``path``, and check its frame-0 world (see :func:`load_scenario_text`)."""
    text = read_scenario(path)
    return load_scenario_text(text, str(path), overrides, extra=extra, base_dir=Path(path).resolve().parent,
                              check_world=check_world, allow_plugins=allow_plugins)


def dump_resolved(scenario: Scenario) -> str:
    """The fully resolved scenario (every field, defaults included) as YAML; loading it gives an equal Scenario."""
    body = yaml.dump(scenario.model_dump(mode="json"), Dumper=_Dumper, sort_keys=False, allow_unicode=True,
                     default_flow_style=False, width=120)
    return f"# fully resolved scenario '{scenario.name}' (every field, defaults included)\n{body}"
