"""Offloading controller and fill strategies: section estimates with holes and noise, decisions, nudges."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cosim.scenario.config import Scenario
from dynamics_proc.control.controller import (
    ControllerParams,
    controller_step,
    initial_controller,
    min2x2,
    section_heights,
)
from dynamics_proc.control.protocol import ControllerInput
from dynamics_proc.control.strategies import back_to_front, front_to_back, get_strategy, lowest_first


def cparams(**controller) -> ControllerParams:
    """The decision logic on the paper-style estimator (the fused one has tests of its own)."""
    controller.setdefault("estimator", "paper")
    return ControllerParams.from_scenario(Scenario.model_validate({"format_version": 1, "controller": controller}))


def test_strategies_pick_expected_sections():
    full = np.array([True, False, False, True, False])
    h = np.array([1.9, 1.5, 1.2, 1.9, np.nan])
    assert front_to_back(full, h, -1) == 1
    assert back_to_front(full, h, -1) == 4
    assert lowest_first(full, h, -1) == 4                      # unknown counts as lowest
    # lowest_first: within LEVEL_BAND_M of the lowest, the nearest one; the current one while it is in band
    h2 = np.array([1.9, 1.5, 1.2, 1.9, 1.3])
    assert lowest_first(full, h2, -1) == 1                     # 1.5 <= 1.2 + 0.3: in band, nearest to the front
    h3 = np.array([1.9, 1.6, 1.2, 1.9, 1.3])
    assert lowest_first(full, h3, -1) == 2                     # 1.6 out of band
    assert lowest_first(full, h3, 4) == 4 and lowest_first(full, h3, 1) == 2
    # front/back finish the current section first; every strategy reports -1 when all are full
    for f in (front_to_back, back_to_front):
        assert f(full, h, 2) == 2
    for f in (front_to_back, back_to_front, lowest_first):
        assert f(np.ones(5, bool), h, 2) == -1
    with pytest.raises(ValueError, match="unknown fill strategy 'spiral'"):
        get_strategy("spiral")


def test_section_heights_truth_holes_and_noise():
    p = cparams()
    m = np.full((p.nx, p.ny), 1.0)
    m[20:24, 10:14] = 1.8                                      # a 4 x 4 heap top in section 4 (rows 20..26)
    est = section_heights(m, p)
    assert est.shape == (9,) and est[3] == pytest.approx(1.8) and np.all(np.delete(est, 3) == 1.0)
    # holes: a section with no valid cell is NaN, the others keep their peak
    m2 = m.copy()
    m2[: p.section_start_rows[1], :] = np.nan
    m2[21, 11] = np.nan
    est2 = section_heights(m2, p)
    assert np.isnan(est2[0]) and est2[3] == pytest.approx(1.8)
    # a single-cell spike (noise) does not raise the estimate
    m3 = m.copy()
    m3[40, 5] = 5.0
    assert section_heights(m3, p)[6] == pytest.approx(1.0)
    # rim returns along the walls (cells centred within 0.2 m of a wall) are left out
    m4 = m.copy()
    m4[:2, :] = 2.06
    m4[:, -2:] = 2.06
    assert np.all(section_heights(m4, p) == section_heights(m, p))
    # a section with fewer than min_section_cells valid cells (outside the edge band) is unknown
    m5 = np.full((p.nx, p.ny), np.nan)
    m5[5:7, 5] = 1.4
    m5[5, 6] = 1.4
    assert np.isnan(section_heights(m5, p)[0])
    m5[6, 6] = 1.4
    assert section_heights(m5, p)[0] == pytest.approx(1.4)


@settings(max_examples=50, deadline=None)
@given(m=st.lists(st.one_of(st.floats(0.0, 3.0), st.just(float("nan"))), min_size=12, max_size=12))
def test_min2x2_never_exceeds_a_valid_neighbour_block(m):
    a = np.array(m).reshape(4, 3)
    f = min2x2(a)
    q = np.pad(a, ((0, 1), (0, 1)), mode="edge")             # independent: explicit edge-replicated blocks
    for i in range(4):
        for j in range(3):
            block = q[i:i + 2, j:j + 2]
            if np.all(np.isnan(block)):
                assert np.isnan(f[i, j])
            else:
                assert f[i, j] == np.nanmin(block)


def _step(st_, p, t, meas, actual=0.35, impacts=((0.35, 1.5), (0.35, 1.5)), signal=0.35):
    inp = ControllerInput(t_s=t, frame=0, heights=meas, spout_x_m=actual, impacts=impacts, drift_x_m=0.0,
                          nudge_signal_m=signal, delivery=None, target_fill_m=p.target_m)
    return controller_step(st_, p, inp)


def test_no_measurement_keeps_auger_off_and_holds():
    p = cparams()
    s0 = initial_controller(p)
    s1, out = _step(s0, p, 0.0, None)
    assert not out.auger_on and out.nudge == 0 and not s1.seen
    s2, out = _step(s1, p, 0.1, np.full((p.nx, p.ny), 1.0))
    assert out.auger_on and s2.target == 0


def test_auger_off_when_unsafe_or_all_full():
    p = cparams()
    s = initial_controller(p)
    meas = np.full((p.nx, p.ny), 1.0)
    _, out = _step(s, p, 0.0, meas, impacts=((0.35, 1.5), (0.35, 2.9)))     # floor landing near the far wall
    assert not out.auger_on
    s, out = _step(s, p, 0.0, np.full((p.nx, p.ny), 1.95))
    assert not out.auger_on and s.all_full and s.target == -1


def test_nudges_respect_size_interval_and_safe_range():
    p = cparams()
    s = initial_controller(p)
    m = np.full((p.nx, p.ny), 1.0)
    m[: p.section_start_rows[2], :] = 1.95                      # sections 1 and 2 full: target section 3 (1.67 m)
    s, out = _step(s, p, 10.0, m)
    assert s.target == 2 and out.nudge == 1 and out.desired_m == pytest.approx(p.centres_m[2])
    s, out = _step(s, p, 10.5, m, signal=0.65)                  # within the 1 s interval: no nudge
    assert out.nudge == 0
    s, out = _step(s, p, 11.0, m, signal=0.65)
    assert out.nudge == 1 and s.nudges == 2
    # the last section's centre (5.67) is not reachable on the 0.35 + 0.3 k lattice without leaving the safe
    # range (5.75 > 6 - 0.3): the controller stays at 5.45
    m = np.full((p.nx, p.ny), 1.95)
    m[p.section_start_rows[8]:, :] = 1.0
    s = initial_controller(p)
    s, out = _step(s, p, 20.0, m, actual=5.45, impacts=((5.45, 1.5),), signal=5.45)
    assert s.target == 8 and out.nudge == 0


def test_stale_target_section_is_given_up():
    p = cparams(stale_timeout_s=2.0)
    s = initial_controller(p)
    m = np.full((p.nx, p.ny), 1.0)
    s, out = _step(s, p, 0.0, m)
    assert s.target == 0 and out.auger_on
    blind = m.copy()
    blind[: p.section_start_rows[1], :] = np.nan                # section 1 never seen again
    t = 0.0
    while t < 5.0 and s.target == 0:
        t += 0.1
        s, out = _step(s, p, t, blind)
    assert s.target == 1 and s.forced_full[0] and 2.0 < t <= 2.3
