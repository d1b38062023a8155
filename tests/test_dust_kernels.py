"""The optimised kernels of the dusty LiDAR frame against their readable references, bit for bit:
``beam_crossings`` against ``beam_crossings_reference`` (perception_proc.atmosphere.crossings) on parabolic streams
seen from outside and from inside their bounding sphere, with repeated rows, a stream along the beams, one segment
and a partial group, and with the beams in a rotated sensor frame; ``kernel_share`` against the disk overlap it
stands for (perception_proc.atmosphere.stream) with kernels inside, across and outside the footprint;
``DustModel.returns`` against ``returns_reference`` (perception_proc.atmosphere.dust) in both return modes on every
kind of range."""
from __future__ import annotations

import math

import numpy as np
import pytest

from perception_proc.atmosphere.crossings import GROUP, beam_crossings, beam_crossings_reference
from perception_proc.atmosphere.dust import DustModel, _table, hard_power
from perception_proc.atmosphere.stream import disk_overlap, kernel_share


def _stream(rng: np.random.Generator, m: int) -> np.ndarray:
    """Rows (m, 4) float32 of a grain stream's parabola: spout about 4.5 m up, 3-5 m/s out, radius 0.1-0.2 m."""
    t = np.linspace(0.0, rng.uniform(0.3, 0.8), m)
    v = rng.uniform(3.0, 5.0) * np.array([math.cos(0.3), math.sin(0.3), -0.2])
    p = np.array([1.0, 7.0, 4.5]) + t[:, None] * v[None, :] - 0.5 * 9.81 * (t ** 2)[:, None] * np.array([0, 0, 1.0])
    radius = np.linspace(0.1, 0.2, m)[:, None]
    return np.hstack([p, radius]).astype(np.float32)


def _beams_at(rng: np.random.Generator, origin: np.ndarray, rows: np.ndarray, n: int, spread: float) -> np.ndarray:
    """``n`` unit directions (n, 3) from ``origin`` towards points within ``spread`` m of the stream's rows."""
    aim = rows[rng.integers(0, len(rows), n), :3].astype(np.float64) + rng.normal(0.0, spread, (n, 3))
    d = aim - origin
    return d / np.linalg.norm(d, axis=1)[:, None]


def _same(got, ref):
    assert len(got) == len(ref) == 4
    for a, b in zip(got, ref):
        assert a.dtype == b.dtype
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("seed", range(4))
def test_crossings_are_the_references_bit_for_bit(seed):
    rng = np.random.default_rng(seed)
    rows = _stream(rng, 64)
    origin = np.array([rng.uniform(-4.0, 0.0), rng.uniform(0.0, 3.0), rng.uniform(3.0, 5.0)])
    d = _beams_at(rng, origin, rows, 30000, 0.25)
    ref = beam_crossings_reference(origin, d, rows)
    assert ref[0].size > 1000 and len(np.unique(ref[1] // GROUP)) > 3   # many crossings, over several groups
    _same(beam_crossings(origin, d, rows), ref)


@pytest.mark.parametrize("seed", range(4))
def test_crossings_of_sensor_frame_beams_turned_by_a_rotation(seed):
    """The beams in the sensor's frame with the sensor's rotation give the reference's crossings of the world
    directions ``directions @ rotation.T`` (the cull in the sensor's frame; the passing rows turned alone)."""
    rng = np.random.default_rng(seed + 20)
    rows = _stream(rng, 64)
    origin = np.array([rng.uniform(-4.0, 0.0), rng.uniform(0.0, 3.0), rng.uniform(3.0, 5.0)])
    rotation = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    rotation *= np.sign(np.linalg.det(rotation))                     # a proper rotation
    world = _beams_at(rng, origin, rows, 30000, 0.25)
    sensor = world @ rotation                                        # the same beams in the sensor's frame
    ref = beam_crossings_reference(origin, sensor @ rotation.T, rows)
    assert ref[0].size > 1000
    _same(beam_crossings(origin, sensor, rows, rotation), ref)


def test_crossings_seen_from_inside_the_stream_and_along_it():
    rng = np.random.default_rng(7)
    rows = _stream(rng, 40)
    inside = rows[20, :3].astype(np.float64) + np.array([0.0, 0.05, 0.0])  # the sensor within the stream itself
    d = np.vstack([_beams_at(rng, inside, rows, 5000, 0.3), rng.normal(size=(5000, 3))])
    d /= np.linalg.norm(d, axis=1)[:, None]
    ref = beam_crossings_reference(inside, d, rows)
    assert ref[0].size > 100
    _same(beam_crossings(inside, d, rows), ref)
    column = np.zeros((12, 4), np.float32)                           # a vertical stream, beams along its axis
    column[:, 2], column[:, 3] = np.linspace(3.0, 0.0, 12), 0.15
    down = np.vstack([[0.0, 0.0, -1.0], _beams_at(rng, np.array([0.05, 0.0, 5.0]), column, 3000, 0.2)])
    ref = beam_crossings_reference(np.array([0.05, 0.0, 5.0]), down, column)
    assert ref[0].size > 20
    _same(beam_crossings(np.array([0.05, 0.0, 5.0]), down, column), ref)


@pytest.mark.parametrize("m", [2, 3, GROUP + 1, 2 * GROUP + 3])
def test_crossings_of_short_streams_repeated_rows_and_none(m):
    rng = np.random.default_rng(m)
    rows = _stream(rng, m)
    rows = np.repeat(rows, 2, axis=0)[1:]                            # every row twice: zero-length segments
    origin = np.array([-2.0, 1.0, 4.0])
    d = _beams_at(rng, origin, rows, 8000, 0.2)
    ref = beam_crossings_reference(origin, d, rows)
    assert ref[0].size > 10
    _same(beam_crossings(origin, d, rows), ref)
    away = -d                                                        # every beam pointing away: no crossing
    assert beam_crossings_reference(origin, away, rows)[0].size == 0
    _same(beam_crossings(origin, away, rows), beam_crossings_reference(origin, away, rows))
    _same(beam_crossings(origin, d, rows[:1]), beam_crossings_reference(origin, d, rows[:1]))


@pytest.mark.parametrize("kernel_d_m", [0.004, 0.008, 0.03])
def test_kernel_share_is_the_disk_overlap_bit_for_bit(kernel_d_m):
    rng = np.random.default_rng(3)
    w = np.concatenate([rng.uniform(1e-3, 0.06, 300), [kernel_d_m, 0.5 * kernel_d_m, 2 * kernel_d_m]])
    k = np.repeat(np.arange(len(w)), rng.integers(0, 60, len(w)))
    reach = 0.5 * (w + kernel_d_m)
    off = reach[k] * np.sqrt(rng.random(k.size))                     # within reach, as occlude draws them
    off[::97] = 0.0
    off[1::89] = reach[k[1::89]] * 1.5                               # beyond reach: no overlap
    off[2::83] = np.abs(0.5 * kernel_d_m - 0.5 * w[k[2::83]])        # exactly touching inside
    ref = np.minimum(disk_overlap(off, 0.5 * kernel_d_m, 0.5 * w[k]) / (math.pi * 0.25 * w[k] ** 2), 1.0)
    got = kernel_share(off, kernel_d_m, w, k)
    assert (ref == 0.0).any() and (ref == 1.0).any() and ((ref > 0.0) & (ref < 1.0)).sum() > 1000
    np.testing.assert_array_equal(got, ref)


@pytest.mark.parametrize("last", [False, True])
@pytest.mark.parametrize("alpha", [0.03, 0.15])
def test_returns_are_the_references_bit_for_bit(last, alpha):
    r_max = 60.0
    grid, peak, at = _table(alpha, alpha / 40.0, 4e-9, 0.5, 2.0, r_max)
    p_min = float(hard_power(r_max, 0.0, 0.1, 0.0, 0.0))
    model = DustModel(alpha, alpha / 40.0, 0.3, 0.5, 2.0, p_min, last, grid, peak, at)
    rng = np.random.default_rng(int(alpha * 100) + last)
    ranges = np.concatenate([rng.uniform(-1.0, r_max + 20.0, 20000), rng.uniform(0.0, 3.0, 5000),
                             grid[::7], [np.nan, np.inf, -np.inf, 0.0, -0.0, 1e-30]]).astype(np.float32)
    ref = model.returns_reference(ranges)
    got = model.returns(ranges)
    assert got.dtype == ref.dtype == np.float32
    assert np.isnan(ref).any() and (ref == ranges).sum() > 1000 and ((ref != ranges) & np.isfinite(ref)).any()
    np.testing.assert_array_equal(got, ref)
    np.testing.assert_array_equal(model.returns(ranges.reshape(-1, 8)), ref.reshape(-1, 8))
    as64 = ranges.astype(np.float64)                                 # not float32: the reference answers
    np.testing.assert_array_equal(model.returns(as64), model.returns_reference(as64))
