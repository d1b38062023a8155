"""Grain fill model: conservation, non-negativity and repose as properties; closed forms for the heap."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cosim.scenario.config import Scenario
from dynamics_proc.grain.fill import (
    GrainGrid,
    deposit,
    initial_heights,
    max_slope,
    relax,
    resample,
    section_rows,
    volume,
)

SLOPE_TOL = 1e-3


def small_grid(repose_deg: float = 23.0, nx: int = 24, ny: int = 12, cell: float = 0.1) -> GrainGrid:
    return GrainGrid(nx, ny, cell, 2.0, math.tan(math.radians(repose_deg)), 0.25)


def test_grid_from_scenario_and_bad_cell():
    s = Scenario(format_version=1)
    g = GrainGrid.from_scenario(s)
    assert (g.nx, g.ny, g.cell_m) == (60, 30, 0.1)
    assert g.tan_repose == pytest.approx(math.tan(math.radians(23.0)))
    with pytest.raises(ValueError, match="does not divide the cart interior length"):   # the record refuses it
        Scenario.model_validate({"format_version": 1, "grain": {"cell_m": 0.07}})
    bad = s.model_copy(update={"grain": s.grain.model_copy(update={"cell_m": 0.07})})   # and so does the grid
    with pytest.raises(ValueError, match="does not divide the cart interior length"):
        GrainGrid.from_scenario(bad)


def test_single_deposit_on_flat_floor_is_the_closed_form_cone():
    """Far from the walls the heap is a cone with a flat top: V = pi r0^2 H + pi t H^2 ... (frustum sum)."""
    g = GrainGrid(200, 200, 0.02, 2.0, math.tan(math.radians(25.0)), 0.25)
    h0 = np.zeros((g.nx, g.ny))
    # a cone of apex height H with flat top r0 has volume pi/3 (H/t) ... computed exactly:
    hh, t, r0 = 0.5, g.tan_repose, 0.25
    r1 = r0 + hh / t
    v_exact = math.pi / 3.0 * hh * (r1 ** 2 + r1 * r0 + r0 ** 2)
    h, spill = deposit(h0, 2.0, 2.0, v_exact, g)
    assert spill == 0.0
    assert h.max() == pytest.approx(hh, rel=2e-3)          # grid discretisation of the cone only
    assert volume(h, g) == pytest.approx(v_exact, rel=1e-12)


@settings(max_examples=60, deadline=None)
@given(
    seq=st.lists(st.tuples(st.floats(0.0, 2.4), st.floats(0.0, 1.2), st.floats(1e-4, 0.6)), min_size=1,
                 max_size=25),
    fill=st.floats(0.0, 2.3), repose=st.sampled_from([23.0, 25.0, 35.0]),
)
def test_deposit_invariants(seq, fill, repose):
    """delivered == in cart + spilled (rel 1e-9), heights >= 0, slopes within tan(repose) + 1e-3."""
    g = small_grid(repose)
    h = initial_heights(g, fill)
    v0 = volume(h, g)
    delivered = spilled = 0.0
    for x, y, v in seq:
        h, s = deposit(h, min(x, g.length_m - 1e-9), min(y, g.width_m - 1e-9), v, g)
        delivered += v
        spilled += s
        assert s >= 0.0
    assert abs(delivered - (volume(h, g) - v0) - spilled) <= 1e-9 * delivered
    assert h.min() >= 0.0
    assert max_slope(h, g.cell_m) <= g.tan_repose + SLOPE_TOL
    assert np.all(h <= g.cap() + 1e-12)


@settings(max_examples=40, deadline=None)
@given(hm=st.lists(st.floats(0.0, 3.0), min_size=8 * 6, max_size=8 * 6), repose=st.sampled_from([23.0, 25.0]))
def test_relax_invariants(hm, repose):
    g = small_grid(repose, nx=8, ny=6)
    h0 = np.array(hm).reshape(8, 6)
    h, spilled = relax(h0, g)
    assert h.min() >= 0.0
    assert max_slope(h, g.cell_m) <= g.tan_repose + SLOPE_TOL
    assert abs(volume(h0, g) - volume(h, g) - spilled) <= 1e-9 * max(volume(h0, g), 1e-12)
    assert spilled >= -1e-12


def test_relax_and_deposit_agree_for_a_point_load():
    """Independent check: dumping a column in one cell and relaxing gives the same volume and peak region as
    the closed-form heap, within a cell of slope."""
    g = small_grid(25.0, nx=40, ny=40, cell=0.05)
    g = GrainGrid(g.nx, g.ny, g.cell_m, g.depth_m, g.tan_repose, 0.025)
    v = 0.05
    h_dep, _ = deposit(np.zeros((40, 40)), 1.025, 1.025, v, g)
    col = np.zeros((40, 40))
    col[20, 20] = v / g.cell_area_m2
    h_rel, sp = relax(col, g, tol_slope=1e-5)
    assert sp == pytest.approx(0.0, abs=1e-12)
    assert volume(h_rel, g) == pytest.approx(volume(h_dep, g), rel=1e-9)
    assert abs(h_rel.max() - h_dep.max()) < 2 * g.tan_repose * g.cell_m


def test_walls_hold_the_heap_and_overflow_spills():
    g = small_grid(23.0)
    h = initial_heights(g, 1.9)
    h2, spill = deposit(h, 0.05, 0.05, 2.0, g)             # a big load in a corner: the cart overflows
    assert spill > 0.0
    assert np.all(h2 <= g.cap() + 1e-12)
    assert h2.max() <= g.depth_m + g.tan_repose * (min(g.length_m, g.width_m) / 2) + 1e-9
    assert max_slope(h2, g.cell_m) <= g.tan_repose + SLOPE_TOL


@pytest.mark.parametrize("vol_m3", [3e-19, 1e-30])
def test_a_volume_below_the_heights_resolution_is_taken(vol_m3):
    """A flow that ramps down in float steps can leave a last volume so small that h + V/A == h in float: the heap
    takes it without changing the heights (conserved to round-off) instead of failing."""
    g = small_grid()
    h = initial_heights(g, 1.5)
    h2, spill = deposit(h, 1.2, 0.6, vol_m3, g)
    np.testing.assert_array_equal(h2, h)
    assert spill == 0.0


@pytest.mark.parametrize("factor,frame_s", [(1.0, 0.1), (10.0, 0.1), (10.0, 0.2)])
def test_stable_at_high_flow_and_long_frames(factor, frame_s):
    g = GrainGrid.from_scenario(Scenario(format_version=1))
    h = initial_heights(g, 1.0)
    v0 = volume(h, g)
    dv = 0.125 * factor * frame_s
    spilled = delivered = 0.0
    for _ in range(int(40.0 / frame_s)):
        h, s = deposit(h, 3.0, 1.5, dv, g)
        spilled += s
        delivered += dv
    assert np.all(np.isfinite(h)) and h.min() >= 0.0
    assert max_slope(h, g.cell_m) <= g.tan_repose + SLOPE_TOL
    assert abs(delivered - (volume(h, g) - v0) - spilled) <= 1e-9 * delivered


def test_resample_block_mean_and_identity():
    h = np.arange(60 * 30, dtype=float).reshape(60, 30)
    assert np.array_equal(resample(h, 0.1, 0.1, 6.0, 3.0), h)
    r = resample(h, 0.1, 0.2, 6.0, 3.0)
    assert r.shape == (30, 15)
    assert r[0, 0] == pytest.approx(h[:2, :2].mean())
    assert r[-1, -1] == pytest.approx(h[-2:, -2:].mean())


def test_section_rows_cover_sections_in_order():
    rows = section_rows(60, 0.1, 6.0, 9)
    assert rows[0] == 0 and rows[-1] == 8 and np.all(np.diff(rows) >= 0)
    centres = (np.arange(60) + 0.5) * 0.1
    w = 6.0 / 9
    expected = [int(np.sum((centres >= k * w) & (centres < (k + 1) * w))) for k in range(9)]
    assert np.bincount(rows).tolist() == expected == [7, 6, 7, 7, 6, 7, 7, 6, 7]
