"""Whether any of a second set of points lies within a radius of each point (2-D, m): the cart search's
"anything right above the rim" test.

Only the points inside the others' bounding box grown by the radius are looked up, by one of two kernels with
the same squared-distance test, hence the same answers: :func:`near_pairs` compares every pair (the plain
reference, and the cheaper one for the few thousand pairs of a run's frames), :func:`near_in_grid` looks in
the 3 x 3 cells of a grid of radius-sized squares around each point (many pairs), after answering at once the
points that share a half-radius square with one of the others (the dense clouds of a dusty frame);
:func:`near_in_grid_plain` is its form without that shortcut. No k-d tree:
scipy.spatial costs a perception process ~0.2 s of start-up.
"""
from __future__ import annotations

import numpy as np

__all__ = ["has_neighbour", "near_pairs", "near_in_grid", "near_in_grid_plain", "PAIRS_MAX"]

#: :func:`has_neighbour` compares every pair up to this many (a (K, M) array), the grid above it
PAIRS_MAX = 1 << 16


def has_neighbour(xy: np.ndarray, others: np.ndarray, radius: float) -> np.ndarray:
    """(K,) bool: whether any of ``others`` (M, 2) lies closer than ``radius`` (m, strictly) to each of ``xy``
    (K, 2), by :func:`near_pairs` or :func:`near_in_grid` on the points near the others' bounding box."""
    lo, hi = others.min(axis=0) - radius, others.max(axis=0) + radius
    near = np.flatnonzero((xy[:, 0] >= lo[0]) & (xy[:, 0] <= hi[0]) & (xy[:, 1] >= lo[1]) & (xy[:, 1] <= hi[1]))
    out = np.zeros(xy.shape[0], bool)
    q = np.take(xy, near, axis=0)
    if near.size * others.shape[0] <= PAIRS_MAX:               # a run's frames: some 40 x 70 pairs
        out[near] = near_pairs(q, others, radius)
    elif near.size:
        out[near] = near_in_grid(q, others, lo, radius)
    return out


def near_pairs(q: np.ndarray, others: np.ndarray, radius: float) -> np.ndarray:
    """(K,) bool for :func:`has_neighbour` by testing every pair of ``q`` (K, 2) and ``others`` (M, 2): the
    plain reference of :func:`near_in_grid` (the same squared-distance test, the same numbers), and the
    cheaper one for a few thousand pairs."""
    d0 = q[:, :1] - others[:, 0]                                # (K, M)
    d1 = q[:, 1:] - others[:, 1]
    return (d0 * d0 + d1 * d1 < radius * radius).any(axis=1)


def _cell_keys(pts: np.ndarray, origin: np.ndarray, side: float) -> tuple[np.ndarray, np.ndarray]:
    """Cell indices (P, 2) int64 >= 0 of points ``pts`` (P, 2) at or beyond ``origin`` in a grid of ``side`` m."""
    return (np.floor((pts[:, 0] - origin[0]) / side).astype(np.int64),
            np.floor((pts[:, 1] - origin[1]) / side).astype(np.int64))


def _shares_half_cell(q: np.ndarray, others: np.ndarray, origin: np.ndarray, radius: float) -> np.ndarray:
    """(K,) bool: whether each of ``q`` (K, 2) lies in the same square of side ``radius / 2`` as one of
    ``others`` (M, 2): two such points are at most ``radius / sqrt(2)`` apart, so the squared-distance test
    answers yes for them with a margin of half of ``radius^2``, far beyond any rounding."""
    oa, ob = _cell_keys(others, origin, 0.5 * radius)
    qa, qb = _cell_keys(q, origin, 0.5 * radius)
    ny = int(max(ob.max(), qb.max())) + 1
    keys = np.unique(oa * ny + ob)
    qkey = qa * ny + qb
    at = np.minimum(np.searchsorted(keys, qkey), keys.size - 1)
    return keys.take(at) == qkey


def near_in_grid(q: np.ndarray, others: np.ndarray, origin: np.ndarray, radius: float) -> np.ndarray:
    """(K,) bool for :func:`has_neighbour`: queries ``q`` (K, 2) inside the box from ``origin`` (the others'
    minimum less the radius, so every cell index below is >= 0 and the others' are >= 1). The queries that share
    a half-radius square with one of the others are answered at once (:func:`_shares_half_cell`: dense clouds,
    such as a dust cloud's returns); the rest look in the 3 x 3 cells around them, the own cell first, a query
    leaving the search at its first neighbour (the answers of the full search, which ORs the cells)."""
    hit = _shares_half_cell(q, others, origin, radius)
    rest = np.flatnonzero(~hit)
    if rest.size == 0:
        return hit
    oa, ob = _cell_keys(others, origin, radius)
    qa, qb = _cell_keys(q, origin, radius)
    # cells as keys a * ny + b; ny leaves two empty columns above the highest, so a neighbour key one column
    # outside the grid (b - 1 = -1 or b + 1) never names an occupied cell
    ny = int(max(ob.max(), qb.max())) + 3
    order = np.argsort(oa * ny + ob, kind="stable")
    keys = (oa * ny + ob).take(order)
    px, py = others[:, 0].take(order), others[:, 1].take(order)
    r2 = radius * radius
    for da, db in ((0, 0), (-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1)):
        key = (qa.take(rest) + da) * ny + (qb.take(rest) + db)
        start = np.searchsorted(keys, key, "left")
        count = np.searchsorted(keys, key, "right") - start
        total = int(count.sum())
        if total == 0:
            continue
        iq = np.repeat(rest, count)
        io = np.repeat(start - (np.cumsum(count) - count), count) + np.arange(total)
        d0, d1 = q[:, 0].take(iq) - px.take(io), q[:, 1].take(iq) - py.take(io)
        hit[iq[d0 * d0 + d1 * d1 < r2]] = True
        rest = rest[~hit.take(rest)]
        if rest.size == 0:
            break
    return hit


def near_in_grid_plain(q: np.ndarray, others: np.ndarray, origin: np.ndarray, radius: float) -> np.ndarray:
    """:func:`near_in_grid` without its half-cell shortcut and early exit (every pair of the 3 x 3 cells tested:
    the readable form, the same answers)."""
    oc = np.floor((others - origin) / radius).astype(np.int64)
    qc = np.floor((q - origin) / radius).astype(np.int64)
    # cells as keys a * ny + b; ny leaves two empty columns above the highest, so a neighbour key one column
    # outside the grid (b - 1 = -1 or b + 1) never names an occupied cell
    ny = int(max(oc[:, 1].max(), qc[:, 1].max())) + 3
    okey = oc[:, 0] * ny + oc[:, 1]
    order = np.argsort(okey, kind="stable")
    keys, pts = okey[order], others[order]
    r2 = radius * radius
    hit = np.zeros(q.shape[0], bool)
    rows = np.arange(q.shape[0])
    for da in (-1, 0, 1):
        for db in (-1, 0, 1):
            key = (qc[:, 0] + da) * ny + (qc[:, 1] + db)
            start = np.searchsorted(keys, key, "left")
            count = np.searchsorted(keys, key, "right") - start
            total = int(count.sum())
            if total == 0:
                continue
            iq = np.repeat(rows, count)
            io = np.repeat(start - (np.cumsum(count) - count), count) + np.arange(total)
            d = q[iq] - pts[io]
            hit[iq[d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] < r2]] = True
    return hit
