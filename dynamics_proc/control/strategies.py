"""Fill strategies: which section to fill next.

A strategy is a pure function ``(full (N,) bool, height (N,) float64 m with NaN unknown, current int) -> int``
returning the 0-based section to fill (front = 0), or -1 when every section is full. ``current`` is the
section being filled (-1 at the start).

* ``front_to_back`` (the paper's): the first section from the front that is not full.
* ``back_to_front``: the first section from the back that is not full.
* ``lowest_first`` (ours, layered): among the not-full sections within LEVEL_BAND_M of the lowest one, the
  nearest to the current section; the current one is kept while it stays in that band. The cart rises in
  layers swept front to back and back again (adjacent moves, so the auger keeps running): the load stays
  level all along (an early stop leaves an even load: 29 cm spread at half time against 61 cm for
  front-to-back, bench/HISTORY.md) and is the most accurate with a noisy, holed map, for up to ~20 % more
  time with ideal feedback.

front_to_back and back_to_front keep filling the current section until it is full.

``controller.strategy`` is a plug-in point (docs/plugins.md): these three are the built-ins, registered as entry
points of the group ``graincosim.strategies`` and resolved by cosim.scenario.plugins like a user's function with
the same signature. :data:`STRATEGIES` / :func:`get_strategy` look up the built-ins alone.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

__all__ = ["Strategy", "front_to_back", "back_to_front", "lowest_first", "STRATEGIES", "get_strategy"]

Strategy = Callable[[np.ndarray, np.ndarray, int], int]

#: lowest_first leaves the current section once it stands this much above the lowest not-full one, m
LEVEL_BAND_M = 0.3


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
    """Layered: among the not-full sections within LEVEL_BAND_M of the lowest one (unknown heights count as
    lowest), the one nearest the current section (ties to the lower); the current section is kept while it
    is within that band. -1 when all are full."""
    idx = np.flatnonzero(~full)
    if not idx.size:
        return -1
    h = np.where(np.isnan(height[idx]), -np.inf, height[idx])
    low = idx[h <= h.min() + LEVEL_BAND_M]
    if current in low:
        return current
    ref = current if current >= 0 else 0
    hl = np.where(np.isnan(height[low]), -np.inf, height[low])
    order = np.lexsort((hl, np.abs(low - ref)))       # by distance, then by height
    return int(low[order[0]])


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
