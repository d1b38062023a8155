"""Checks every value of a scenario document passes, whatever key holds it (plug-in options and FMU parameters
included), before the document is validated against the records.

* a number is finite: ``.nan`` / ``.inf`` (or 1e400, which YAML reads as infinity) are refused at their own key,
  so that no NaN reaches a child (JSON has no NaN: it would arrive as ``null``);
* an integer fits 64 bits (what every consumer of one, numpy and the FMI API included, can hold);
* text (values and keys) holds no control character but tab and line feed (an escape sequence typed into a
  terminal, a NUL byte): such text would reach file names, logs and terminals.

Nesting depth and document size are limited by the parser (cosim.scenario.yamlmarks.MAX_DEPTH, MAX_VALUES).
"""
from __future__ import annotations

import math
import unicodedata

from .yamlmarks import Doc, Loc, show

__all__ = ["value_problems", "MAX_INT", "TEXT_CONTROLS_ALLOWED"]

#: largest magnitude of an integer value (int64)
MAX_INT = 2**63 - 1
#: control characters text may hold
TEXT_CONTROLS_ALLOWED = frozenset("\t\n")


def _control(text: str) -> tuple[int, str] | None:
    """(index, character) of the first control character of ``text`` that is not allowed, None when none."""
    for i, ch in enumerate(text):
        if ch not in TEXT_CONTROLS_ALLOWED and unicodedata.category(ch) == "Cc":
            return i, ch
    return None


def _why(value, what: str = "text") -> str | None:
    """Why ``value`` (a scalar) is refused, None when it is not."""
    if isinstance(value, float) and not math.isfinite(value):
        return f"{show(value)} is not a finite number: a number here must be finite"
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) > MAX_INT:
        return f"{show(value)} does not fit a 64-bit integer (|n| <= {MAX_INT})"
    if isinstance(value, str):
        bad = _control(value)
        if bad is not None:
            return (f"{what} {show(value)} holds the control character U+{ord(bad[1]):04X} at position {bad[0]}: text "
                    "may hold tabs and line breaks, no other control characters")
    return None


def value_problems(doc: Doc) -> set[Loc]:
    """Add a problem to ``doc`` for every value (and key) it refuses; the set of keys reported."""
    reported: set[Loc] = set()
    stack: list[tuple[Loc, object]] = [((), doc.data)]
    while stack:
        loc, node = stack.pop()
        if isinstance(node, dict):
            for key, value in node.items():
                why = _why(key, "key")
                if why is not None:
                    doc.problem(doc.keys.get(loc + (key,), doc.values[()]), loc + (key,), why)
                    reported.add(loc + (key,))
                stack.append((loc + (key,), value))
        elif isinstance(node, list):
            stack.extend((loc + (i,), v) for i, v in enumerate(node))
        else:
            why = _why(node)
            if why is not None:
                doc.problem(doc.values.get(loc, doc.values[()]), loc, why)
                reported.add(loc)
    return reported
