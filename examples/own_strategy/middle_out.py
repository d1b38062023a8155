"""A fill strategy of our own: fill the cart from the middle outwards.

The middle section first, then the not-full section nearest the middle (ties to the front), keeping the
current section until it is full. Loading the middle first puts the weight over the cart's axle early, so a
load stopped half way leaves the cart balanced instead of nose- or tail-heavy.

Protocol (graincosim ``controller.strategy``, dynamics_proc.control.strategies): ``(full (N,) bool, height (N,) float64 m
with NaN unknown, current int) -> int``, the 0-based section to fill next (front = 0), or -1 when every
section is full. It is called once per sensor frame once a measurement has arrived.
"""
from __future__ import annotations

import numpy as np

__all__ = ["middle_out", "middle_out_order"]


def middle_out_order(n: int, middle: float | None = None) -> list[int]:
    """The order middle-out visits ``n`` sections when each is filled in turn: ``middle`` (0-based; None: the
    cart's middle, (n - 1) / 2), then by distance from it (ties to the front)."""
    centre = (n - 1) / 2.0 if middle is None else float(middle)
    return sorted(range(n), key=lambda i: (abs(i - centre), i))


def middle_out(full: np.ndarray, height: np.ndarray, current: int, *, middle: float | None = None) -> int:
    """The current section while it is not full, else the not-full section nearest ``middle`` (an option:
    ``controller.strategy_options.middle``, 0-based; the cart's middle when not given); -1 when all are full."""
    if 0 <= current < full.size and not full[current]:
        return current
    for i in middle_out_order(full.size, middle):
        if not full[i]:
            return i
    return -1
