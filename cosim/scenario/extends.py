"""``extends: NAME_OR_PATH``: a scenario that starts from another one and states only what differs.

The base is a packaged scenario by name (``extends: default``) or a file: a value with a ``.yaml`` / ``.yml``
suffix or a ``/`` is a path, relative to the folder of the file that names it. The base is read (and may extend
another in turn, up to :data:`MAX_CHAIN` files), then the file's own keys are merged over it as ``--set`` merges
them: a mapping merges key by key, anything else (a value, a list) replaces. ``name`` and ``description`` are not
inherited: they describe the file itself (left out, they take the record defaults). ``sensors:`` and the
one-LiDAR shorthand ``sensor:`` replace each other: a file that gives one of them and not the other does not
inherit the other from its base (a base's ``sensors:`` merge with a file's ``sensors:`` by name, as any mapping).
A mapping both give (``controller:``) is the file's: a problem of the section is reported at the file's key.

Every value keeps the marks of the file it comes from, so a problem in an inherited value is reported at the
base file's line, and a relative path is resolved against the folder of the file that gave it
(:func:`apply_extends` returns the folder of each file). A base that does not exist, cannot be read, is of
another ``format_version``, or closes a cycle is a problem at the ``extends`` line.
"""
from __future__ import annotations

import os
from pathlib import Path

from cosim.errors import ScenarioError

from .config import FORMAT_VERSION
from .files import _unknown, packaged_scenarios, read_scenario
from .overrides import assign
from .yamlmarks import Doc, parse, show

__all__ = ["EXTENDS_KEY", "MAX_CHAIN", "NOT_INHERITED", "EXCLUSIVE", "EXTENDS_DESCRIPTION", "apply_extends", "base_of"]

#: the key that names a scenario's base
EXTENDS_KEY = "extends"
#: most files in one chain of bases (a longer chain is surely a mistake)
MAX_CHAIN = 16
#: keys a file does not inherit from its base
NOT_INHERITED = ("name", "description")
#: (key, the base's key it replaces): a file that gives the one and not the other does not inherit the other
#: (``sensors:`` replaces the one-LiDAR shorthand ``sensor:`` of its base, and back)
EXCLUSIVE = (("sensors", "sensor"), ("sensor", "sensors"))
#: the key's description (the JSON Schema carries it)
EXTENDS_DESCRIPTION = (
    "Start from another scenario and state only what differs: the name of a packaged scenario (`launch.py list`) "
    "or a path to a scenario file (a value with a .yaml/.yml suffix or a '/'), relative to this file's folder. "
    "Mappings merge key by key, other values replace; name and description are not inherited."
)


def base_of(value: str, folder: Path) -> tuple[Path | None, str]:
    """(the base file ``value`` names, '') or (None, why it names none); a path is relative to ``folder``."""
    if Path(value).suffix in (".yaml", ".yml") or "/" in value or os.sep in value:
        path = (folder / Path(value).expanduser()).resolve()
        if path.is_file():
            return path, ""
        return None, f"base scenario file {str(path)!r} does not exist (a path is relative to {str(folder)!r})"
    packaged = packaged_scenarios()
    if value in packaged:
        return packaged[value].resolve(), ""
    return None, _unknown(value)


def _drop(doc: Doc, key: str) -> None:
    doc.data.pop(key, None)
    for marks in (doc.keys, doc.values):
        for stale in [p for p in marks if p[:1] == (key,)]:
            del marks[stale]


def apply_extends(doc: Doc, filename: str, folder: Path,
                  chain: tuple[Path, ...] = ()) -> tuple[Doc, dict[str, Path]]:
    """``doc`` (of ``filename`` in ``folder``) merged over its chain of bases; and file name -> folder of every
    file whose values it holds (to resolve relative paths against). Problems go to the returned document."""
    folders = {filename: folder}
    if not isinstance(doc.data, dict) or EXTENDS_KEY not in doc.data:
        return doc, folders
    value = doc.data[EXTENDS_KEY]
    mark = doc.values.get((EXTENDS_KEY,), doc.values[()])
    _drop(doc, EXTENDS_KEY)
    here = (EXTENDS_KEY,)
    if not isinstance(value, str) or not value.strip():
        doc.problem(mark, here, f"expected the name of a packaged scenario or a path to a scenario file, got "
                                f"{show(value)}")
        return doc, folders
    path, why = base_of(value, folder)
    if path is None:
        doc.problem(mark, here, why)
        return doc, folders
    names = [p.name for p in chain] + ([Path(filename).name] if Path(filename).is_file() else [])
    if path in chain or (Path(filename).is_file() and path == Path(filename).resolve()):
        doc.problem(mark, here, f"the bases form a cycle: {' -> '.join(names + [path.name])}")
        return doc, folders
    if len(chain) + 1 >= MAX_CHAIN:
        doc.problem(mark, here, f"more than {MAX_CHAIN} files extend one another ({' -> '.join(names)} -> ...)")
        return doc, folders
    try:
        text = read_scenario(path)
    except ScenarioError as e:
        doc.problem(mark, here, e.problems[0].message)
        return doc, folders
    base = parse(text, str(path))
    if base.problems and not base.values:       # a syntax error in the base: nothing to merge
        doc.problems += base.problems
        return doc, folders
    if not isinstance(base.data, dict) or base.data.get("format_version") != FORMAT_VERSION:
        what = "not a mapping" if not isinstance(base.data, dict) else \
            f"of format_version {show(base.data.get('format_version'))}"
        doc.problem(mark, here, f"base scenario {str(path)!r} is {what}; this version of graincosim reads "
                                f"format_version: {FORMAT_VERSION}")
        return doc, folders
    own = Path(filename).resolve() if Path(filename).is_file() else None
    base, base_folders = apply_extends(base, str(path), path.parent, chain + ((own,) if own else ()))
    for key in NOT_INHERITED:
        _drop(base, key)
    for own_key, other in EXCLUSIVE:
        if own_key in doc.data and other not in doc.data:
            _drop(base, other)
    for key, item in doc.data.items():
        assign(base, (key,), item, doc, (key,), doc.keys[(key,)])
    base.keys.update(doc.keys)              # a mapping both give is the file's: its problems at the file's key
    base.values.update(doc.values)
    base.values[()] = base.keys[()] = doc.values[()]
    base.problems = doc.problems + base.problems
    return base, {**base_folders, **folders}
