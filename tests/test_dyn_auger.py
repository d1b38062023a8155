"""Auger: spout pose, flow ramps, ballistic stream and its first surface, against closed forms."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import quad

from cosim.scenario.config import Scenario
from cosim.world.geometry import cart_grid_from_body, invert, vehicle_pose
from dynamics_proc.grain import auger as ag


def params(**auger) -> ag.AugerParams:
    return ag.AugerParams.from_scenario(Scenario.model_validate({"format_version": 1, "auger": auger}))


def test_spout_closed_form_and_yaw():
    a = params()
    sp = ag.spout_world(0.0, 0.0, 0.0, a)
    el = math.radians(8.0)
    np.testing.assert_allclose(sp, [-2.0, 1.5 + 6.0 * math.cos(el), 3.8 + 6.0 * math.sin(el)], atol=1e-12)
    # turning the combine by 90 deg turns the spout about the combine origin
    sp2 = ag.spout_world(10.0, 5.0, math.pi / 2, a)
    np.testing.assert_allclose(sp2, [10.0 - sp[1], 5.0 + sp[0], sp[2]], atol=1e-12)
    v = ag.exit_velocity_world(0.0, a)
    assert np.linalg.norm(v) == pytest.approx(3.0)
    assert v[2] == pytest.approx(-3.0 * math.sin(math.radians(60.0)))


@settings(max_examples=60, deadline=None)
@given(level=st.floats(0.0, 1.0), on=st.booleans(), dt=st.floats(1e-3, 3.0), up=st.floats(0.0, 2.0),
       down=st.floats(0.0, 2.0))
def test_flow_volume_is_the_integral_of_the_ramp(level, on, dt, up, down):
    a = params(spool_up_s=up, run_out_s=down)
    new, vol = ag.flow_advance(level, on, dt, a)
    # independent: adaptive quadrature of the clipped linear level, told where the kink is
    ramp = up if on else down
    sign = 1.0 if on else -1.0
    if ramp <= ag.MIN_RAMP_S:
        ref = (1.0 if on else 0.0) * dt
    else:
        def lv(t):
            return min(max(level + sign * t / ramp, 0.0), 1.0)
        kink = ((1.0 - level) if on else level) * ramp
        ref = quad(lv, 0.0, dt, points=[kink] if 0.0 < kink < dt else None, epsabs=1e-13, epsrel=1e-12)[0]
    assert vol == pytest.approx(a.flow_m3ps * ref, rel=1e-9, abs=1e-15)
    assert 0.0 <= new <= 1.0


def _frames(cart_xy=(-4.65, 7.4)):
    s = Scenario(format_version=1)
    g = cart_grid_from_body(s.cart) @ invert(vehicle_pose(cart_xy[0], cart_xy[1], 0.0))
    return s, g


def test_impact_on_flat_grain_matches_the_parabola():
    s, g = _frames()
    a = ag.AugerParams.from_scenario(s)
    sp = ag.spout_world(0.0, 0.0, 0.0, a)
    vel = ag.exit_velocity_world(0.0, a)
    h = np.full((60, 30), 1.0)
    imp = ag.first_surface(sp, vel, g, h, 0.1, a)
    # closed form: fall from sp_z to floor + 1.0 = 2.0 m
    dz = sp[2] - 2.0
    t = (vel[2] + math.sqrt(vel[2] ** 2 + 2 * ag.GRAVITY_MPS2 * dz)) / ag.GRAVITY_MPS2
    assert imp.surface == ag.SURFACE_GRAIN
    assert imp.time_s == pytest.approx(t, rel=2e-4)
    np.testing.assert_allclose(imp.world[:2], sp[:2] + vel[:2] * t, atol=1e-3)
    assert imp.world[2] == pytest.approx(2.0, abs=1e-9)
    assert imp.grid[0] == pytest.approx(0.35, abs=1e-3)       # first section, as the defaults promise
    # landing_point agrees with the same closed form
    lp = ag.landing_point(sp, vel, 2.0)
    np.testing.assert_allclose(lp, [*(sp[:2] + vel[:2] * t), 2.0], atol=1e-9)


def test_impact_on_rim_and_ground_are_classified():
    s, _ = _frames()
    a = ag.AugerParams.from_scenario(s)
    sp = ag.spout_world(0.0, 0.0, 0.0, a)
    vel = ag.exit_velocity_world(0.0, a)
    h = np.zeros((60, 30))
    # cart far away: the stream reaches the ground
    _, g_far = _frames((-40.0, 7.4))
    imp = ag.first_surface(sp, vel, g_far, h, 0.1, a)
    assert imp.surface == ag.SURFACE_GROUND and imp.world[2] == pytest.approx(0.0, abs=1e-9)
    # cart placed so that the closed-form landing point at rim height is on the left rim band
    z_rim = s.cart.floor_height_m + a.rim_top_m
    lp = ag.landing_point(sp, vel, z_rim)
    cart_y = lp[1] - (s.cart.interior_width_m / 2.0 + 0.05)      # 5 cm into the 12 cm band
    _, g_rim = _frames((-4.65, cart_y))
    imp = ag.first_surface(sp, vel, g_rim, h, 0.1, a)
    assert imp.surface == ag.SURFACE_WALL
    assert imp.world[2] == pytest.approx(z_rim, abs=1e-9)


def test_stream_rows_shape_and_ends():
    s, g = _frames()
    a = ag.AugerParams.from_scenario(s)
    sp = ag.spout_world(0.0, 0.0, 0.0, a)
    vel = ag.exit_velocity_world(0.0, a)
    imp = ag.first_surface(sp, vel, g, np.full((60, 30), 1.0), 0.1, a)
    out = np.zeros((ag.STREAM_ROWS, 4), np.float32)
    rows = ag.stream_rows(sp, vel, imp.time_s, 0.15, out=out)
    assert rows is out and rows.dtype == np.float32 and rows.shape == (64, 4)
    np.testing.assert_allclose(rows[0, :3], sp, atol=1e-5)
    np.testing.assert_allclose(rows[-1, :3], imp.world, atol=2e-3)
    assert np.all(np.diff(rows[:, 2]) < 0)                 # falling all the way


@settings(max_examples=100, deadline=None)
@given(spout=st.lists(st.floats(-10.0, 10.0), min_size=3, max_size=3),
       vel=st.lists(st.floats(-8.0, 8.0), min_size=3, max_size=3), z=st.floats(-2.0, 12.0))
def test_landing_xy_is_landing_point_to_the_bit(spout, vel, z):
    s, v = np.array(spout), np.array(vel)
    assert list(ag.landing_xy(s, v, z)) == ag.landing_point(s, v, z)[:2].tolist()
