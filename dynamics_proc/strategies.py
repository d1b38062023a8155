"""Fill strategies: which section to fill next.

A strategy is a pure function ``(full (N,) bool, height (N,) float64 m with NaN unknown, current int) -> int``
returning the 0-based section to fill (front = 0), or -1 when every section is full. ``current`` is the
section being filled (-1 at the start). All of them keep filling the current section until it is full, so
the auger never dithers between sections.

* ``front_to_back`` (the paper's): the first section from the front that is not full.
* ``back_to_front``: the first section from the back that is not full.
* ``lowest_first`` (ours): the not-full section with the lowest estimated height, ties (and unknown heights,
  which count as lowest) to the one nearest the current section. Filling the lowest place first keeps the
  profile level, so the heap of one section does not spill grain into the next before it is aimed at, and
  ending sections are not left short when the operator stops early; it moves the auger only as far as needed.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

__all__ = ["Strategy", "front_to_back", "back_to_front", "lowest_first", "STRATEGIES", "get_strategy"]

Strategy = Callable[[np.ndarray, np.ndarray, int], int]


def front_to_back(full: np.ndarray, height: np.ndarray, current: int) -> int:
    """First not-full section from the front; -1 when all are full."""
    if 0 <= current < full.size and not full[current]:
        return current
    idx = np.flatnonzero(~full)
    return int(idx[0]) if idx.size else -1


def back_to_front(full: np.ndarray, height: np.ndarray, current: int) -> int:
    """First not-full section from the back; -1 when all are full."""
    if 0 <= current < full.size and not full[current]:
        return current
    idx = np.flatnonzero(~full)
    return int(idx[-1]) if idx.size else -1


def lowest_first(full: np.ndarray, height: np.ndarray, current: int) -> int:
    """Lowest not-full section (unknown heights lowest; ties to the nearest one); -1 when all are full."""
    if 0 <= current < full.size and not full[current]:
        return current
    idx = np.flatnonzero(~full)
    if not idx.size:
        return -1
    h = np.where(np.isnan(height[idx]), -np.inf, height[idx])
    ref = current if current >= 0 else 0
    order = np.lexsort((np.abs(idx - ref), h))        # by height, then by distance
    return int(idx[order[0]])


STRATEGIES: dict[str, Strategy] = {
    "front_to_back": front_to_back,
    "back_to_front": back_to_front,
    "lowest_first": lowest_first,
}


def get_strategy(name: str) -> Strategy:
    """The strategy called ``name``; ValueError naming the choices otherwise."""
    try:
        return STRATEGIES[name]
    except KeyError:
        raise ValueError(f"unknown fill strategy {name!r}; choose one of {sorted(STRATEGIES)}") from None
