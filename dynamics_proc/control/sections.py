"""Section estimates of a height map on the controller grid (dynamics_proc.control.controller): the robust peak of each
section (the highest NaN-ignoring 2 x 2 block minimum, blocks kept inside their section, cells within the edge
margin left out) and whether a map shows a section at all. Pure functions of the map and the controller's
constants (anything with ``nx``, ``edge_cells``, ``section_start_rows``, ``min_section_cells``)."""
from __future__ import annotations

from functools import lru_cache

import numpy as np

__all__ = ["min2x2", "section_blocks", "section_valid", "section_heights", "section_pairing", "inner_cells"]


def min2x2(m: np.ndarray, next_row: np.ndarray | None = None) -> np.ndarray:
    """NaN-ignoring minimum over each 2 x 2 block of cells, (nx, ny) float64 m; NaN only where the whole
    block is NaN. A single noisy cell cannot raise it. ``next_row`` (nx,) int: the row paired with each row
    (default i + 1, the last row with itself); the last column pairs with itself."""
    m = np.asarray(m, dtype=np.float64)
    nx, ny = m.shape
    if next_row is None:
        next_row = np.minimum(np.arange(nx) + 1, nx - 1)
    col = np.minimum(np.arange(ny) + 1, ny - 1)
    pair = np.fmin(m, m[next_row])                 # each cell with its row pair
    return np.fmin(pair, pair[:, col])             # = fmin(fmin(m, down), fmin(m[:, col], down[:, col]))


def inner_cells(m: np.ndarray, p) -> np.ndarray:
    """A float64 copy of ``m`` (nx, ny) m with the cells within the edge margin set to NaN."""
    ex, ey = p.edge_cells
    m = np.array(m, dtype=np.float64)
    if ex:
        m[:ex], m[-ex:] = np.nan, np.nan
    if ey:
        m[:, :ey], m[:, -ey:] = np.nan, np.nan
    return m


def section_valid(m: np.ndarray, p) -> np.ndarray:
    """Whether each section of ``m`` (nx, ny) m has at least ``min_section_cells`` valid cells inside the edge
    margin, (N,) bool."""
    valid = np.count_nonzero(~np.isnan(inner_cells(m, p)), axis=1)
    return np.add.reduceat(valid, section_pairing(p.nx, p.section_start_rows)[0]) >= p.min_section_cells


@lru_cache(maxsize=8)
def section_pairing(nx: int, section_start_rows: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
    """(first row of each section (N,), row paired with each row (nx,)): the next one, the last row of a section
    with itself, so that 2 x 2 blocks stay inside their section. Read-only, computed once per grid."""
    starts = np.asarray(section_start_rows)
    nxt = np.minimum(np.arange(nx) + 1, nx - 1)
    last = np.append(starts[1:], nx) - 1
    nxt[last] = last
    starts.setflags(write=False)
    nxt.setflags(write=False)
    return starts, nxt


def section_blocks(m: np.ndarray, p) -> tuple[np.ndarray, np.ndarray]:
    """(``m`` with the edge margin NaN (:func:`inner_cells`), its 2 x 2 block minima kept inside their sections
    (:func:`min2x2`)), both (nx, ny) float64 m: what :func:`section_heights` reads, for a caller that also needs
    the blocks (the estimate's peak sigma)."""
    m = inner_cells(m, p)
    return m, min2x2(m, section_pairing(p.nx, p.section_start_rows)[1])


def section_heights(m: np.ndarray, p, blocks: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """Robust peak per section: the highest 2 x 2 block minimum (blocks stay inside their section; cells within
    the edge margin left out), (N,) float64 m; NaN where a section has fewer than ``min_section_cells`` valid
    cells. Exact for a heap whose flat top spans 2 x 2 cells. ``blocks``: :func:`section_blocks` of ``m``, where
    the caller has them already."""
    m, b = section_blocks(m, p) if blocks is None else blocks
    starts = section_pairing(p.nx, p.section_start_rows)[0]
    rowmax = np.fmax.reduce(b, axis=1)                       # NaN only for all-NaN rows
    peak = np.fmax.reduceat(rowmax, starts)
    valid = np.add.reduceat(np.count_nonzero(~np.isnan(m), axis=1), starts)
    return np.where(valid >= p.min_section_cells, peak, np.nan)
