"""Dust and the grain stream for the LiDAR (perception_proc.atmosphere.dust, stream_particles, lidar_atmosphere): the
clear-air limit is today's ranges, the uniform medium against its closed forms, the reported return, the stream's
kernels as partial occluders."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import quad

from cosim.scenario.config import Scenario
from perception_proc.atmosphere.crossings import beam_crossings
from perception_proc.atmosphere.dust import C_MPS, dust_model, hard_power, overlap, soft_power
from perception_proc.atmosphere.lidar import lidar_atmosphere, stream_row_time
from perception_proc.atmosphere.stream import disk_overlap, kernel_density, occlude

TAU = 20e-9
R1, R2 = 0.9, 1.0


def scen(**atm) -> Scenario:
    return Scenario.model_validate({"format_version": 1, "atmosphere": atm})


def test_clear_air_changes_nothing_and_its_limit_is_todays_ranges():
    assert scen().atmosphere.clear and lidar_atmosphere(scen(), np.eye(3)) is None
    s = scen(visibility_m=1e4)                                      # 10 km: the clear-air limit
    r = np.linspace(0.5, s.sensor.range_max_m, 5000).astype(np.float32)
    r[::7] = np.nan                                                  # beams that met nothing
    out = dust_model(s).returns(r)
    assert np.array_equal(out, r, equal_nan=True)


def test_the_visibility_sets_the_extinction_and_the_lidar_ratio_the_backscatter():
    m = dust_model(scen(visibility_m=100.0, lidar_ratio_sr=60.0))
    assert m.alpha == pytest.approx(math.log(20.0) / 100.0) and m.beta == pytest.approx(m.alpha / 60.0)
    assert scen(dust_mass_g_m3=0.05, mass_extinction_m2_per_g=0.5).atmosphere.extinction_per_m == pytest.approx(0.025)


def test_a_hard_return_through_a_uniform_medium_is_attenuated_twice_its_path():
    alpha = 0.1
    r = np.array([2.0, 5.0, 10.0])
    assert hard_power(r, alpha, 0.3, R1, R2) / hard_power(r, 0.0, 0.3, R1, R2) == pytest.approx(np.exp(-2 * alpha * r))
    assert hard_power(r, 0.0, 0.3, R1, R2) == pytest.approx(0.3 / math.pi / r ** 2)
    assert overlap([0.5, 0.95, 2.0], R1, R2) == pytest.approx([0.0, 0.5, 1.0])


@pytest.mark.parametrize("alpha", [0.01, 0.1])
def test_the_mediums_return_is_the_pulse_convolved_with_the_backscatter(alpha):
    beta, length = alpha / 60.0, C_MPS * TAU
    for r in (1.5, 3.0, 7.0, 20.0):
        def f(x, r=r):
            return (math.sin(math.pi * (r - x) / length) ** 2 * float(overlap(x, R1, R2)) * math.exp(-2 * alpha * x)
                    / x ** 2)
        ref = beta * quad(f, max(r - length, R1), r, points=[R2], limit=200)[0]
        assert soft_power(r, alpha, beta, TAU, R1, R2)[0] == pytest.approx(ref, rel=2e-3)
    far = 400.0                                                      # far from the sensor: beta (c tau / 2) T^2 / R^2
    assert soft_power(far, 1e-4, 1e-6, TAU, R1, R2)[0] == pytest.approx(1e-6 * length / 2 * math.exp(-2e-4 * far)
                                                                         / far ** 2, rel=0.02)


def test_the_reported_return_strongest_or_last():
    dense = scen(visibility_m=25.0)
    ranges = np.array([3.0, 9.0, 30.0, np.nan], np.float32)
    strongest = dust_model(dense).returns(ranges)
    m = dust_model(dense)
    assert strongest[0] == ranges[0]                                 # a near target outshines the dust
    assert 1.0 < strongest[1] < 6.0                                  # a far one: a false early return
    assert 1.0 < strongest[3] < 6.0                                  # and where the beam met nothing
    last = dust_model(scen(visibility_m=25.0, return_mode="last")).returns(ranges)
    assert last[1] == ranges[1]                                      # last: the target while it is detected
    h = hard_power(ranges[2], m.alpha, m.reflectivity, R1, R2)
    assert h < m.p_min and 1.0 < last[2] < 6.0                       # lost in the dust: its last return is the dust


def test_disk_overlap_closed_forms():
    assert disk_overlap(0.0, 1.0, 2.0) == pytest.approx(math.pi)     # contained
    assert disk_overlap(3.5, 1.0, 2.0) == 0.0                        # apart
    lens = 2 * math.acos(0.5) - 0.5 * math.sqrt(3.0)                 # two unit disks, centres 1 apart
    assert disk_overlap(1.0, 1.0, 1.0) == pytest.approx(lens)


def _vertical_stream(radius=0.15, n=64):
    rows = np.zeros((n, 4))
    rows[:, 0], rows[:, 2], rows[:, 3] = 5.0, np.linspace(3.0, 0.0, n), radius
    return rows


def test_a_beam_crosses_the_stream_along_its_exact_chord():
    rows = _vertical_stream()
    delta = 0.1                                                      # the beam passes 0.1 m from the axis
    d = np.array([[1.0, 0.0, 0.0]])
    beams, seg, mid, chord = beam_crossings(np.array([0.0, delta, 1.51]), d, rows)
    assert beams.tolist() == [0] and mid[0] == pytest.approx(5.0)
    assert chord[0] == pytest.approx(2 * math.sqrt(0.15 ** 2 - delta ** 2))
    assert beam_crossings(np.array([0.0, 0.2, 1.5]), d, rows)[0].size == 0


def test_kernels_share_a_beam_with_its_target_and_thin_or_dense_streams_behave():
    rng = np.random.default_rng(0)
    ranges = np.array([9.0, 9.0])
    beams, mids, chords = np.array([0, 1]), np.array([5.0, 5.0]), np.array([0.3, 0.01])
    ids, row, r, took, left = occlude(ranges, beams, mids, chords, np.array([7e5, 7e5]), 0.008, 3e-3, rng)
    total = np.bincount(row, weights=took, minlength=len(ids)) + left
    assert total == pytest.approx(np.ones(len(ids)))                 # the shares sum to 1
    assert left[0] < 1e-3 and np.all((r > 4.84) & (r < 5.16))        # 0.3 m of stream: opaque, hit inside it
    assert len(ids) < 2 or left[1] > 0.1                             # 1 cm of its fringe: mostly through
    again = occlude(ranges, beams, mids, chords, np.array([7e5, 7e5]), 0.008, 3e-3, np.random.default_rng(0))
    assert np.array_equal(again[2], r)
    dt = stream_row_time(_vertical_stream(), 3.0, math.radians(60.0))
    assert kernel_density(_vertical_stream(), 0.0, 0.6, 0.008, dt).max() == 0.0


def test_the_stream_as_particles_in_a_lidar_frame():
    s = Scenario.model_validate({"format_version": 1, "atmosphere": {"stream_particles": True}})
    rows = np.zeros((64, 4), np.float32)
    rows[:] = _vertical_stream()
    d = np.array([[1.0, 0.0, 0.0], [1.0, 0.5, 0.0]]) / np.linalg.norm([[1.0, 0.0, 0.0], [1.0, 0.5, 0.0]], axis=1)[:, None]
    atm = lidar_atmosphere(s, d)
    pose = np.eye(4)
    pose[:3, 3] = (0.0, 0.0, 1.5)
    state = {"stream_points": 64, "flow_m3ps": 0.125}
    out = atm.apply(np.array([9.0, 9.0], np.float32), 3, state, rows, pose)
    assert 4.84 < out[0] < 5.16 and out[1] == np.float32(9.0)       # the stream's kernels, and a beam that misses
    assert np.array_equal(out, atm.apply(np.array([9.0, 9.0], np.float32), 3, state, rows, pose))
    assert atm.apply(np.array([9.0, 9.0], np.float32), 3, {"stream_points": 0}, rows, pose)[0] == 9.0


def test_a_dust_gust_blows_only_over_its_window():
    s = Scenario.model_validate_json('{"format_version": 1, "atmosphere": {"visibility_m": 25.0, '
                                     '"dust_window_s": [10.0, 20.0]}}')
    atm = lidar_atmosphere(s, np.array([[0.0, 0.0, 1.0]]))
    r = np.array([9.0], np.float32)
    before, during = atm.apply(r, 1, {"t_s": 9.9}, None, np.eye(4)), atm.apply(r, 1, {"t_s": 10.0}, None, np.eye(4))
    assert before[0] == 9.0 and 1.0 < during[0] < 6.0 and atm.apply(r, 1, {"t_s": 20.0}, None, np.eye(4))[0] == 9.0
