"""The cart found where Machine Sync puts it, or no cart (perception_proc.estimates.posegate): a phantom in dust is
rejected, a cart found within the gate passes unchanged."""
from __future__ import annotations

import math

import numpy as np
import pytest

from cosim.scenario.loader import load_scenario_text
from perception_proc.estimates.impact import Impact
from perception_proc.estimates.posegate import expected_cart, pose_gate
from perception_proc.estimates.rim import CartEstimate
from perception_proc.pipeline import FrameResult

STATE = {"cart_x_m": 10.0, "cart_y_m": 5.0, "cart_yaw_rad": 0.2, "combine_yaw_rad": math.pi / 2,
         "gnss_error_long_m": 0.03, "gnss_error_lat_m": -0.02}


def _found(x, y, yaw):
    cart = CartEstimate(True, np.zeros((4, 3)), np.eye(4), yaw, (x, y), 500, False, "")
    return FrameResult(None, cart, object(), Impact(True, np.ones(3), 40, ""), {"cart": 1.0})


def _wfp(dx, dy, yaw):
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0, dx], [s, c, 0, dy], [0, 0, 1, 0], [0, 0, 0, 1.0]])


def test_machine_syncs_cart_is_the_true_one_moved_by_the_tractors_gnss_error_in_combine_axes():
    x, y, yaw = expected_cart(STATE)                   # combine heading +y: long error along +y, lat along -x
    assert (x, y, yaw) == pytest.approx((10.0 + 0.02, 5.0 + 0.03, 0.2), abs=1e-12)
    assert expected_cart({"t_s": 1.0}) is None


def test_a_cart_found_where_machine_sync_puts_it_passes_and_a_phantom_is_rejected():
    wfp = _wfp(2.0, 1.0, 0.1)                          # the level frame in the world: moved and turned
    x, y, yaw = expected_cart(STATE)
    c, s = math.cos(-0.1), math.sin(-0.1)
    lx, ly = c * (x - 2.0) - s * (y - 1.0), s * (x - 2.0) + c * (y - 1.0)    # the expected cart, level frame
    near = _found(lx + 0.3, ly - 0.3, yaw - 0.1 + math.radians(4.0))       # 0.42 m, 4 deg: within the gate
    assert pose_gate(near, STATE, wfp, 0.5, 5.0) is near
    for phantom in (_found(lx + 1.2, ly, yaw - 0.1), _found(lx, ly, yaw - 0.1 + math.radians(14.8))):
        out = pose_gate(phantom, STATE, wfp, 0.5, 5.0)
        assert not out.cart.valid and out.heightmap is None and not out.impact.valid
        assert "from where Machine Sync puts the cart: not the cart" in out.cart.reason
        assert out.cart.n_points == 500 and out.timing_ms == phantom.timing_ms
    far = _found(lx + 1.2, ly, yaw - 0.1)
    assert pose_gate(far, STATE, wfp, 0.0, 5.0) is far                    # 0: no gate
    assert pose_gate(far, {}, wfp, 0.5, 5.0) is far                       # no state: nothing to compare


def test_the_gate_is_a_validated_scenario_key():
    s = load_scenario_text("format_version: 1\nrenderer: mock\n", "s.yaml")
    assert (s.perception.pose_gate_m, s.perception.pose_gate_deg) == (0.5, 5.0)
    with pytest.raises(Exception, match=r"s.yaml:3:\d+: perception.pose_gate_deg"):
        load_scenario_text("format_version: 1\nperception:\n  pose_gate_deg: 200.0\n", "s.yaml")
