"""The stream kernels' order by beam then range (perception_proc.atmosphere.stream.beam_range_order) against its
reference, ``np.lexsort``: equal on random kernels, with ties (left to lexsort), one beam, none, non-finite ranges;
and ``occlude`` against its plain form (every kernel's share, then the front ones kept, sorted by lexsort)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from perception_proc.atmosphere.stream import MAX_KERNELS, beam_range_order, disk_overlap, occlude


@pytest.mark.parametrize("seed", range(5))
def test_order_is_lexsorts(seed):
    rng = np.random.default_rng(seed)
    beam = rng.integers(0, 40000, 5000)[rng.integers(0, 300, 20000)]
    r = rng.uniform(0.5, 12.0, beam.size)
    np.testing.assert_array_equal(beam_range_order(beam, r), np.lexsort((r, beam)))


def test_ties_empty_and_nonfinite_fall_back_to_lexsort():
    beam = np.array([3, 1, 3, 1, 2, 3])
    r = np.array([1.0, 2.0, 1.0, 0.5, 7.0, 0.25])               # equal keys: 1.0 twice on beam 3
    np.testing.assert_array_equal(beam_range_order(beam, r), np.lexsort((r, beam)))
    assert beam_range_order(np.zeros(0, np.int64), np.zeros(0)).size == 0
    r[4] = np.inf
    np.testing.assert_array_equal(beam_range_order(beam, r), np.lexsort((r, beam)))
    one = np.zeros(4, np.int64)
    np.testing.assert_array_equal(beam_range_order(one, np.array([3.0, -1.0, 2.0, 0.0])), [1, 3, 2, 0])


def test_ranges_closer_than_the_keys_resolution_and_wide_spreads_keep_lexsorts_order():
    rng = np.random.default_rng(11)
    beam = rng.integers(0, 50, 3000)
    r = rng.uniform(2.0, 9.0, beam.size)
    r[1::2] = np.nextafter(r[::2], np.inf)[: r[1::2].size]           # pairs one ulp apart: equal fixed-point keys
    beam[1::2] = beam[::2][: beam[1::2].size]
    np.testing.assert_array_equal(beam_range_order(beam, r), np.lexsort((r, beam)))
    wide = rng.uniform(0.0, 2.0 ** 40, beam.size)                    # too wide for the fixed-point bits
    np.testing.assert_array_equal(beam_range_order(beam, wide), np.lexsort((wide, beam)))
    many = rng.integers(0, 60000, 200000)                             # many beams, many kernels
    rr = rng.uniform(0.0, 30.0, many.size)
    np.testing.assert_array_equal(beam_range_order(many, rr), np.lexsort((rr, many)))


def _occlude_plain(ranges, beams, mids, chords, density, kernel_d_m, divergence_rad, rng):
    """``occlude`` as first written: the shares of every kernel, then the ones before the target, by lexsort."""
    w = divergence_rad * np.maximum(mids, 1e-3)
    reach = 0.5 * (w + kernel_d_m)
    counts = np.minimum(rng.poisson(density * math.pi * reach * reach * chords), MAX_KERNELS)
    k = np.repeat(np.arange(len(beams)), counts)
    r = (mids - 0.5 * chords)[k] + chords[k] * rng.random(k.size)
    off = reach[k] * np.sqrt(rng.random(k.size))
    share = np.minimum(disk_overlap(off, 0.5 * kernel_d_m, 0.5 * w[k]) / (math.pi * 0.25 * w[k] ** 2), 1.0)
    beam = beams[k]
    target = ranges[beam]
    front = ~(np.isfinite(target) & (r >= target))
    beam, r, share = beam[front], r[front], share[front]
    order = np.lexsort((r, beam))
    beam, r, share = beam[order], r[order], share[order]
    starts = np.concatenate([[True], beam[1:] != beam[:-1]])
    first = np.flatnonzero(starts)
    ids, row = beam[first], np.cumsum(starts) - 1
    logs = np.log1p(-np.minimum(share, 1.0 - 1e-12))
    cum = np.cumsum(logs)
    start = np.concatenate([[0.0], cum])[first][row]
    before = np.exp(np.concatenate([[0.0], cum[:-1]]) - start)
    return ids, row, r, before * share, np.exp(np.add.reduceat(logs, first))


@pytest.mark.parametrize("seed", range(3))
def test_occlude_is_its_plain_form_bit_for_bit(seed):
    rng = np.random.default_rng(seed)
    n_beams, n_cross = 2000, 600
    ranges = np.where(rng.random(n_beams) < 0.2, np.nan, rng.uniform(3.0, 9.0, n_beams))
    beams = np.sort(rng.integers(0, n_beams, n_cross))
    mids, chords = rng.uniform(2.0, 8.0, n_cross), rng.uniform(0.05, 0.6, n_cross)
    density = rng.uniform(1e4, 2e5, n_cross)
    args = (ranges, beams, mids, chords, density, 0.006, 3e-3)
    got = occlude(*args, np.random.default_rng(seed + 10))
    ref = _occlude_plain(*args, np.random.default_rng(seed + 10))
    assert got[2].size > 1000
    for a, b in zip(got, ref):
        np.testing.assert_array_equal(a, b)
