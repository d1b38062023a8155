"""Interleaved rounds and their statistics.

A measurement is repeated in rounds; within a round every arm (a source tree or a setting) is measured once, the
order alternating from round to round (A B, B A, ...), so that a load that drifts during the run falls on every
arm alike. Figures are medians over the rounds with their range; the cost of an arm against the first one is the
median of each round's own ratio ("paired"), which cancels a machine whose speed drifts between rounds.

A sample (one arm, one round) is a set of tables: ``{table title: {row label: {column: value}}}``, values numbers,
strings or None. :func:`aggregate` turns a list of samples into the same shape with a :class:`Stat` per number.
"""
from __future__ import annotations

import math
import statistics
from dataclasses import dataclass
from typing import Iterable, Sequence, TypeVar

__all__ = ["Sample", "Stat", "aggregate", "alternating", "paired_ratios", "rotating", "stat"]

T = TypeVar("T")
#: one measurement of one arm: {table title: {row label: {column: value}}}
Sample = dict


def alternating(items: Sequence[T], round_index: int) -> list[T]:
    """``items`` in order in even rounds and reversed in odd ones (A B, B A, ...)."""
    return list(items) if round_index % 2 == 0 else list(items)[::-1]


def rotating(items: Sequence[T], index: int) -> list[T]:
    """``items`` rotated left by ``index`` (each item first in turn: frame-by-frame interleaving of many arms)."""
    k = index % len(items) if items else 0
    return list(items[k:]) + list(items[:k])


@dataclass(frozen=True)
class Stat:
    """Median, smallest and largest of ``n`` values."""

    median: float
    lo: float
    hi: float
    n: int

    def as_dict(self) -> dict:
        return {"median": self.median, "min": self.lo, "max": self.hi, "n": self.n}


def _number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def stat(values: Iterable[float]) -> Stat | None:
    """The :class:`Stat` of the finite numbers among ``values`` (None when there are none)."""
    v = [x for x in values if _number(x)]
    return Stat(statistics.median(v), min(v), max(v), len(v)) if v else None


def _keys(dicts: Iterable[dict]) -> list:
    """Keys of every dict in first-seen order."""
    out: dict = {}
    for d in dicts:
        out.update(dict.fromkeys(d))
    return list(out)


def aggregate(samples: Sequence[Sample]) -> dict:
    """Per table, row and column: the :class:`Stat` over the samples of the numbers, or the text the samples
    wrote (a label; each round's where they differ, :func:`_texts`)."""
    out: dict = {}
    for table in _keys(samples):
        rows = [s.get(table, {}) for s in samples]
        out[table] = {}
        for row in _keys(rows):
            cells = [r.get(row, {}) for r in rows]
            out[table][row] = {}
            for col in _keys(cells):
                values = [c.get(col) for c in cells]
                if any(_number(v) for v in values):
                    out[table][row][col] = stat(values)
                else:
                    out[table][row][col] = _texts(values)
    return out


def _texts(values: Sequence) -> str | None:
    """The rounds' text of one cell: the text where every round that wrote one agrees, else each round's in
    order, ``" / "``-joined (a verdict that differs between rounds is not one round's word)."""
    texts = [v for v in values if v not in (None, "")]
    if not texts:
        return None
    return texts[0] if len(set(texts)) == 1 else " / ".join(f"round {i + 1}: {v}" for i, v in enumerate(values)
                                                           if v not in (None, ""))


def paired_ratios(base: Sequence[Sample], other: Sequence[Sample], columns: Sequence[str] = ()) -> dict:
    """Per table, row and column (``columns`` only, where given): the :class:`Stat` of each round's ratio of
    ``other`` to ``base`` (rounds paired by index; a round where either is missing or the base is 0 is left out);
    for text (a digest, a verdict) ``same`` where every round's text equals the base's, else ``differs``."""
    out: dict = {}
    pairs = list(zip(base, other))
    for table in _keys(s for s, _ in pairs):
        for row in _keys(s.get(table, {}) for s, _ in pairs):
            for col in _keys(s.get(table, {}).get(row, {}) for s, _ in pairs):
                if columns and col not in columns:
                    continue
                ratios, texts = [], []
                for a, b in pairs:
                    x, y = a.get(table, {}).get(row, {}).get(col), b.get(table, {}).get(row, {}).get(col)
                    if _number(x) and _number(y) and x != 0:
                        ratios.append(y / x)
                    elif isinstance(x, str) and isinstance(y, str):
                        texts.append(x == y)
                s = stat(ratios) if ratios else ("same" if all(texts) else "differs") if texts else None
                if s is not None:
                    out.setdefault(table, {}).setdefault(row, {})[col] = s
    return out
