"""YAML with positions: plain data plus the 1-based line/col of every key and value, YAML 1.2 scalars.

``parse(text, file)`` composes one document and returns a :class:`Doc` (data, key marks, value marks, problems).
YAML 1.2 core schema: ``1e-8`` is a number, ``yes``/``on`` are strings, only ``true``/``false`` are booleans,
dates stay strings. Duplicate keys are reported at their second occurrence; merge keys, non-string keys and
unknown tags are problems, never silently accepted.
"""
from __future__ import annotations

import json
import re
from dataclasses import dataclass, field

import yaml

from cosim.errors import Problem

__all__ = ["Loader", "Dumper", "Mark", "Doc", "Loc", "INVALID", "MAX_VALUES", "MAX_DEPTH", "parse", "build", "dotted",
           "show", "INT_12", "FLOAT_12", "BOOL_12"]

MAX_SHOWN = 60  # characters of an offending input value quoted in a message
#: most values (scalars, lists, mappings) a document may expand to, aliases counted each time they are used: a
#: scenario has a few hundred; an alias bomb ("billion laughs") is refused after this many, in milliseconds
MAX_VALUES = 20_000
#: deepest nesting of mappings and lists a document may have: a scenario nests 5 deep (plug-in options a few more);
#: deeper input (a YAML nested 20,000 deep) is refused as soon as the composer reaches this depth
MAX_DEPTH = 32

BOOL_12 = re.compile(r"^(?:true|True|TRUE|false|False|FALSE)$")
INT_12 = re.compile(r"^(?:[-+]?(?:0|[1-9][0-9]*)|0x[0-9a-fA-F]+|0o[0-7]+)$")
FLOAT_12 = re.compile(
    r"^(?:[-+]?(?:\.[0-9]+|[0-9]+(?:\.[0-9]*)?)(?:[eE][-+]?[0-9]+)?|[-+]?\.(?:inf|Inf|INF)|\.(?:nan|NaN|NAN))$"
)
_REPLACED = {"tag:yaml.org,2002:bool", "tag:yaml.org,2002:int", "tag:yaml.org,2002:float",
             "tag:yaml.org,2002:timestamp"}


class TooDeep(yaml.MarkedYAMLError):
    """Raised by :class:`Loader` when a document nests deeper than MAX_DEPTH."""


class Loader(yaml.SafeLoader):
    """SafeLoader with YAML 1.2 core-schema scalars (no yes/no/on/off booleans, no dates, 1e-8 is a float) and
    a nesting limit (MAX_DEPTH), so that a deeply nested document is refused instead of exhausting the stack."""

    _depth = 0

    def compose_node(self, parent, index):
        self._depth += 1
        try:
            if self._depth > MAX_DEPTH:
                raise TooDeep(None, None, f"the document nests deeper than {MAX_DEPTH} levels (mappings and lists); "
                              "nothing else was checked", self.peek_event().start_mark)
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1


Loader.yaml_implicit_resolvers = {
    ch: [r for r in rs if r[0] not in _REPLACED] for ch, rs in yaml.SafeLoader.yaml_implicit_resolvers.items()
}
Loader.add_implicit_resolver("tag:yaml.org,2002:bool", BOOL_12, list("tTfF"))
Loader.add_implicit_resolver("tag:yaml.org,2002:int", INT_12, list("-+0123456789"))
Loader.add_implicit_resolver("tag:yaml.org,2002:float", FLOAT_12, list("-+0123456789."))


class Dumper(yaml.SafeDumper):
    """SafeDumper that also quotes strings a YAML 1.2 reader would take for numbers (so both readers agree)."""


Dumper.add_implicit_resolver("tag:yaml.org,2002:int", INT_12, list("-+0123456789"))
Dumper.add_implicit_resolver("tag:yaml.org,2002:float", FLOAT_12, list("-+0123456789."))
#: characters YAML reads as line breaks inside a plain or folded scalar (they would come back as spaces)
YAML_BREAKS = frozenset("\x85\u2028\u2029")


def _represent_str(dumper: yaml.SafeDumper, text: str):
    """Double-quote (escaping them) strings holding YAML line-break characters, so they load back unchanged."""
    style = '"' if YAML_BREAKS.intersection(text) else None
    return dumper.represent_scalar("tag:yaml.org,2002:str", text, style=style)


Dumper.add_representer(str, _represent_str)
Dumper.add_representer(list, lambda dumper, seq: dumper.represent_sequence("tag:yaml.org,2002:seq", seq, flow_style=True))

Loc = tuple  # path into the data: str keys and int list indices
INVALID = object()  # a node already reported as a problem: left out of the data (its field keeps its default)


class _AliasBomb(Exception):
    """Raised by :func:`build` when a document exceeds MAX_VALUES; carries the one problem to report."""

    def __init__(self, problem: Problem):
        super().__init__(str(problem))
        self.problem = problem


@dataclass(frozen=True)
class Mark:
    file: str
    line: int
    col: int


@dataclass
class Doc:
    """Plain data plus the marks of every mapping key and value node, by path."""

    data: object = None
    keys: dict[Loc, Mark] = field(default_factory=dict)
    values: dict[Loc, Mark] = field(default_factory=dict)
    problems: list[Problem] = field(default_factory=list)
    #: values still allowed before the document counts as an alias bomb (see MAX_VALUES)
    budget: int = MAX_VALUES

    def problem(self, mark: Mark, loc: Loc, message: str) -> None:
        self.problems.append(Problem(mark.file, mark.line, mark.col, dotted(loc), message))


def dotted(loc: Loc) -> str:
    """``('a', 'b', 0)`` -> ``a.b[0]``; a key that is not printable is shown escaped (``a\\x1bb``), so that a
    message never carries a control character to the terminal."""
    out = ""
    for part in loc:
        if isinstance(part, str) and not part.isprintable():
            part = part.encode("unicode_escape").decode("ascii")
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out


def show(value: object) -> str:
    text = repr(value) if isinstance(value, str) else json.dumps(value, default=str)
    return text if len(text) <= MAX_SHOWN else text[: MAX_SHOWN - 3] + "..."


def parse(text: str, file: str, line0: int = 0, col0: int = 0) -> Doc:
    """Compose ``text`` and build plain data with marks. ``line0``/``col0`` shift marks (for ``--set`` values)."""
    doc = Doc()

    def mark(m: yaml.Mark) -> Mark:  # 1-based; an override is one line: its position in the list of overrides
        return Mark(file, line0 or m.line + 1, col0 + m.column + 1)

    try:
        loader = Loader(text)
    except yaml.reader.ReaderError as e:  # a control character (NUL, ESC, ...) anywhere in the text
        return _reader_problem(doc, e, text, file, line0, col0)
    try:
        try:
            node = loader.get_single_node()
        except TooDeep as e:
            at = mark(e.problem_mark)
            doc.problems.append(Problem(file, at.line, at.col, "", e.problem))
            return doc
        except yaml.reader.ReaderError as e:
            return _reader_problem(doc, e, text, file, line0, col0)
        except yaml.MarkedYAMLError as e:
            m, cm = e.problem_mark or e.context_mark, e.context_mark
            what = e.problem or e.context or "invalid YAML"
            if e.context and e.problem and cm is not None:
                what += f" ({e.context} started at {mark(cm).line}:{mark(cm).col})"
            doc.problems.append(Problem(file, *((mark(m).line, mark(m).col) if m else (0, 0)), "",
                                        f"YAML syntax error: {what}"))
            return doc
        doc.values[()] = doc.keys[()] = mark(node.start_mark) if node else Mark(file, max(line0, 1), 1)
        try:
            doc.data = build(node, (), doc, loader, mark, set()) if node is not None else None
        except _AliasBomb as bomb:  # nothing to go on: report it alone, as a syntax error is
            return Doc(problems=[bomb.problem])
        doc.data = None if doc.data is INVALID else doc.data
    finally:
        loader.dispose()
    return doc


def _reader_problem(doc: Doc, e: yaml.reader.ReaderError, text: str, file: str, line0: int, col0: int) -> Doc:
    """The one problem of a text holding a character YAML does not accept (a control character, NUL)."""
    before = text[: max(0, e.position)]
    line = line0 or before.count("\n") + 1
    col = col0 + e.position - (before.rfind("\n") + 1) + 1
    what = f"U+{e.character:04X}" if isinstance(e.character, int) else repr(e.character)
    doc.problems.append(Problem(file, line, col, "", f"control character {what} in the text: a scenario holds "
                                "printable text only (tabs and line breaks allowed); nothing else was checked"))
    return doc


def build(node, loc: Loc, doc: Doc, loader: Loader, mark, stack: set[int]):
    doc.budget -= 1
    if doc.budget < 0:
        at = mark(node.start_mark)
        raise _AliasBomb(Problem(at.file, at.line, at.col, dotted(loc),
                                 f"the document expands to more than {MAX_VALUES:,} values (YAML aliases used over "
                                 "and over?); nothing else was checked"))
    here = mark(node.start_mark)
    if isinstance(node, yaml.ScalarNode):
        try:
            value = loader.construct_object(node, deep=True)
        except yaml.YAMLError as e:
            doc.problem(here, loc, f"cannot read value: {getattr(e, 'problem', e)}")
            return INVALID
        if value is not None and not isinstance(value, (str, int, float, bool)):
            doc.problem(here, loc, f"unsupported YAML value of type {type(value).__name__} (tag {node.tag})")
            return INVALID
        return value
    if id(node) in stack:
        doc.problem(here, loc, "recursive alias")
        return INVALID
    stack = stack | {id(node)}
    if isinstance(node, yaml.SequenceNode):
        out_list = []
        for i, item in enumerate(node.value):
            doc.keys[loc + (i,)] = doc.values[loc + (i,)] = mark(item.start_mark)
            value = build(item, loc + (i,), doc, loader, mark, stack)
            out_list.append(None if value is INVALID else value)
        return out_list
    out: dict[str, object] = {}
    first: dict[str, Mark] = {}
    for knode, vnode in node.value:
        kmark = mark(knode.start_mark)
        if knode.tag == "tag:yaml.org,2002:merge":
            doc.problem(kmark, loc, "merge keys ('<<') are not supported; write the keys out")
            continue
        key = build(knode, loc, doc, loader, mark, stack) if isinstance(knode, yaml.ScalarNode) else None
        if key is INVALID:
            continue
        if not isinstance(key, str):
            doc.problem(kmark, loc, f"keys must be strings, got {show(key) if key is not None else knode.tag}")
            continue
        if key in first:
            doc.problem(kmark, loc + (key,), f"duplicate key '{key}' (first defined at line {first[key].line})")
            continue
        first[key] = kmark
        doc.keys[loc + (key,)] = kmark
        doc.values[loc + (key,)] = mark(vnode.start_mark)
        value = build(vnode, loc + (key,), doc, loader, mark, stack)
        if value is not INVALID:
            out[key] = value
    return out


# --------------------------------------------------------------------------------------------- model walk
