"""Beam patterns as data, range limits and the noise model."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cosim.scenario.config import Noise, Pattern, Sensor
from cosim.world.patterns import (
    HONEYCOMB_DENSITY_RATIO,
    HONEYCOMB_VFOV_DEG,
    PatternError,
    beam_table,
    honeycomb_elevations,
    load_csv_table,
    pattern_shape,
    validate_table,
)
from perception_proc.lidar.sensor import (
    apply_noise_and_limits,
    frame_generator,
    point_basis,
    to_points,
    to_points_reference,
)


def test_grid_is_uniform_with_both_ends_in_image_order():
    p = Pattern(preset="grid", elevation_min_deg=-10, elevation_max_deg=20, azimuth_min_deg=-30,
                azimuth_max_deg=30, elevation_count=7, azimuth_count=13)
    e, a = beam_table(p)
    assert e.shape == a.shape == (91,) and e.dtype == a.dtype == np.float64
    E, A = np.degrees(e).reshape(7, 13), np.degrees(a).reshape(7, 13)
    np.testing.assert_allclose(E[:, 0], np.linspace(20, -10, 7))              # top row first
    np.testing.assert_allclose(A[0], np.linspace(30, -30, 13))                # leftmost (largest) first
    assert np.ptp(E, axis=1).max() == 0 and np.ptp(A, axis=0).max() == 0
    assert pattern_shape(p) == (7, 13)


def test_honeycomb_spans_95_deg_and_is_denser_at_the_horizon():
    p = Pattern(preset="honeycomb", azimuth_min_deg=-60, azimuth_max_deg=60, azimuth_count=50, elevation_count=64)
    e, a = beam_table(p)
    rings = np.degrees(e.reshape(64, 50)[:, 0])
    assert rings[0] - rings[-1] == pytest.approx(HONEYCOMB_VFOV_DEG)
    assert np.all(np.diff(rings) < 0)
    gaps = -np.diff(rings)
    assert gaps.max() / gaps.min() == pytest.approx(HONEYCOMB_DENSITY_RATIO, rel=0.1)
    assert gaps[len(gaps) // 2] < gaps[0]                                     # denser near the horizon
    np.testing.assert_allclose(np.degrees(a[:50]), np.linspace(60, -60, 50))


@settings(max_examples=50, deadline=None)
@given(count=st.integers(1, 500), ratio=st.floats(1.0, 20.0))
def test_honeycomb_elevations_monotonic_and_bounded(count, ratio):
    e = honeycomb_elevations(count, density_ratio=ratio)
    assert e.shape == (count,)
    assert np.all(np.abs(e) <= math.radians(HONEYCOMB_VFOV_DEG) / 2 + 1e-12)
    assert np.all(np.diff(e) < 0)


def test_csv_table_round_trip_and_errors(tmp_path):
    f = tmp_path / "beams.csv"
    f.write_text("elevation_deg,azimuth_deg\n-10,5\n0,0\n\n12.5,-40\n")
    e, a = beam_table(Pattern(preset="csv", csv_file=f))
    np.testing.assert_allclose(np.degrees(e), [-10, 0, 12.5])
    np.testing.assert_allclose(np.degrees(a), [5, 0, -40])
    assert pattern_shape(Pattern(preset="csv", csv_file=f)) is None
    bad = tmp_path / "bad.csv"
    bad.write_text("elevation_deg,azimuth_deg\n95,0\n")
    with pytest.raises(PatternError, match=r"elevation 95 deg lies outside \[-90, 90\]"):
        load_csv_table(bad)
    bad.write_text("elevation_deg,azimuth_deg\nnan,0\n")
    with pytest.raises(PatternError, match="non-finite"):
        load_csv_table(bad)
    bad.write_text("elev,az\n1,2\n")
    with pytest.raises(PatternError, match="header must start"):
        load_csv_table(bad)
    bad.write_text("elevation_deg,azimuth_deg\n1,x\n")
    with pytest.raises(PatternError, match=r":2: not a number"):
        load_csv_table(bad)
    with pytest.raises(PatternError, match="cannot read"):
        load_csv_table(tmp_path / "missing.csv")
    bad.write_text("elevation_deg,azimuth_deg\n")
    with pytest.raises(PatternError, match="empty"):
        load_csv_table(bad)


def test_validate_table_shapes():
    with pytest.raises(PatternError, match="equal length"):
        validate_table(np.zeros(3), np.zeros(4))


def test_range_limits_make_returns_invalid_not_clamped():
    s = Sensor(range_min_m=1.0, range_max_m=10.0)
    r = np.array([0.5, 1.0, 5.0, 10.0, 10.5, np.nan], np.float32)
    out = apply_noise_and_limits(r.copy(), s, None)
    np.testing.assert_array_equal(np.isnan(out), [True, False, False, False, True, True])
    np.testing.assert_array_equal(out[1:4], [1.0, 5.0, 10.0])


def test_noise_statistics_and_seeding():
    s = Sensor(noise=Noise(range_sigma_m=0.02, dropout=0.1), range_max_m=100.0)
    r0 = np.full(200_000, 20.0, np.float32)
    out = apply_noise_and_limits(r0.copy(), s, frame_generator(5, 3))
    ok = np.isfinite(out)
    assert (1 - ok.mean()) == pytest.approx(0.1, abs=0.005)
    assert np.std(out[ok] - 20.0) == pytest.approx(0.02, rel=0.02)
    assert abs(np.mean(out[ok] - 20.0)) < 3 * 0.02 / math.sqrt(ok.sum())
    again = apply_noise_and_limits(r0.copy(), s, frame_generator(5, 3))
    np.testing.assert_array_equal(out, again)
    other = apply_noise_and_limits(r0.copy(), s, frame_generator(5, 4))
    assert not np.array_equal(np.isnan(out), np.isnan(other))
    with pytest.raises(ValueError, match="frame must be >= 0"):
        frame_generator(5, -1)


def test_points_record_rows():
    d = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
    out = np.empty((2, 4), np.float32)
    res = to_points(d, np.array([2.0, np.nan], np.float32), out=out)
    assert np.shares_memory(res, out)
    np.testing.assert_array_equal(res[0], [0, 0, 2, 2])
    assert np.isnan(res[1]).all()


@pytest.mark.parametrize("n", [0, 1, 7, 38_400])
def test_points_kernel_matches_its_reference_bit_for_bit(n):
    """The OpenCV record (basis x range in four channels) against the numpy column loop: the same float32 bits,
    NaN, infinities, signed zeros and all-invalid frames included, written into ``out`` itself."""
    rng = np.random.default_rng(n)
    d = rng.normal(size=(n, 3))
    d /= np.maximum(np.linalg.norm(d, axis=1), 1e-12)[:, None]
    basis = point_basis(d)
    r = (rng.random(n) * 80.0).astype(np.float32)
    r[::5] = np.nan
    r[1::11] = np.inf
    r[2::13] = -0.0
    r[3::17] = 0.0
    for ranges in (r, np.full(n, np.nan, np.float32)):
        out = np.empty((n, 4), np.float32)
        res = to_points(basis, ranges, out=out)
        assert res is out
        ref = to_points_reference(basis, ranges)
        assert res.tobytes() == ref.tobytes()
        assert to_points(basis, ranges).tobytes() == ref.tobytes()
    # another layout or dtype takes the reference path, with its numbers
    r64 = r.astype(np.float64)
    assert to_points(basis, r64).tobytes() == to_points_reference(basis, r64).tobytes()
    strided = np.empty((n, 8), np.float32)[:, :4]
    assert to_points(basis, r, out=strided).tobytes() == to_points_reference(basis, r).tobytes()



@pytest.mark.parametrize("sigma, dropout", [(0.0, 0.0), (0.05, 0.0), (0.0, 0.1)])
def test_noisy_seeds_a_generator_only_for_a_model_that_draws(monkeypatch, sigma, dropout):
    """Perception.noisy makes the frame's generator only where the noise model draws from it; the ranges are
    those of apply_noise_and_limits with the frame's generator either way (a quiet model: the limits alone)."""
    from cosim.scenario.config import Scenario
    from perception_proc import pipeline

    sc = Scenario(format_version=1, sensor={"method": "beam_native", "noise": {"range_sigma_m": sigma,
                                                                             "dropout": dropout}})
    perc = pipeline.Perception(sc, None)
    made = []
    monkeypatch.setattr(pipeline, "frame_generator", lambda seed, frame: made.append(frame) or
                        frame_generator(seed, frame))
    r = np.linspace(0.0, 200.0, perc.n_beams, dtype=np.float32)
    r[::7] = np.nan
    got = perc.noisy(r.copy(), 11)
    assert made == ([] if sigma == 0.0 and dropout == 0.0 else [11])
    want = apply_noise_and_limits(r.copy(), sc.lidar, frame_generator(sc.seed, 11))
    assert got.tobytes() == want.tobytes()
