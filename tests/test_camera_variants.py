"""Held-out variants of the packaged camera scenarios (examples/camera_variants, docs/cameras.md) and the cameras'
own expected error (perception_proc.cameras.expected): a camera either fills the cart or, where its expected
error at the cart is more than the target allows, stops safe before the auger starts, naming its figure."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from cosim.scenario.config.cameras import DepthCamera, StereoCamera
from cosim.scenario.loader import load_scenario
from perception_proc.cameras.expected import MATCHER_DD_RATIO, cart_depth_m, cell_sigma_m, point_sigma_m
from perception_proc.selection import judge, unfit_reason

VARIANTS = Path(__file__).resolve().parents[1] / "examples" / "camera_variants"
#: the acceptance: at most this much above the target, m
MAX_OVERFILL_M = 0.05
S21B = StereoCamera(kind="stereo_camera", profile="multisense_s21b", mount={"parent": "world"})


def test_a_stereo_points_sigma_is_z_squared_sigma_d_over_f_b():
    f = S21B.focal_px
    assert point_sigma_m(S21B, f, 4.0) == pytest.approx(16.0 * 0.25 / (f * 0.21), rel=1e-12)
    assert point_sigma_m(S21B, f, 8.0) == pytest.approx(4.0 * point_sigma_m(S21B, f, 4.0), rel=1e-12)
    tof = DepthCamera(kind="depth_camera", mount={"parent": "world"})
    assert point_sigma_m(tof, 300.0, 2.4) == pytest.approx(0.0012 + 0.0019 * 2.0**2, rel=1e-12)


def test_each_matcher_has_its_own_disparity_error_in_the_law_and_the_gate():
    """sigma_Z = Z^2 dd / (f B) with the matcher's dd: the profile's 0.25 px for SGBM, 1.36 times that for BM. At
    4.3 m (the packaged spout head 0.3 m higher) a cell's sigma is 2.2 cm with SGBM, fit for the 2.5 cm the 5 cm
    tolerance allows, and 2.9 cm with BM, refused naming StereoBM's 0.34 px."""
    bm = S21B.model_copy(update={"matcher": "bm"})
    f, b = S21B.focal_px, S21B.baseline_m
    assert MATCHER_DD_RATIO["sgbm"] == 1.0 and MATCHER_DD_RATIO["bm"] > 1.2
    assert point_sigma_m(S21B, f, 4.0) == pytest.approx(16.0 * 0.25 / (f * b), rel=1e-12)
    assert point_sigma_m(bm, f, 4.0) == pytest.approx(16.0 * 0.25 * MATCHER_DD_RATIO["bm"] / (f * b), rel=1e-12)
    sigmas = {"sgbm": (cell_sigma_m(S21B, f, 4, 0.1, 4.3), 4.3), "bm": (cell_sigma_m(bm, f, 4, 0.1, 4.3), 4.3)}
    fits = judge(sigmas, 0.05, {"bm": "StereoBM, disparity 1-sigma 0.34 px"})
    assert 0.020 < fits["sgbm"].sigma_m < 0.025 and not fits["sgbm"].unfit
    assert 0.025 < fits["bm"].sigma_m < 0.032 and fits["bm"].unfit
    assert "(StereoBM, disparity 1-sigma 0.34 px)" in unfit_reason("bm", fits["bm"])


def test_a_cells_sigma_divides_by_the_independent_blocks_it_spans():
    """A 0.1 m cell at 4 m spans 0.1 f / 4 px; stereo's blocks (5 px > stride 4) make n = (that / 5)^2; a cell
    smaller than one block keeps the point's sigma."""
    f = S21B.focal_px
    n = (0.1 * f / 4.0 / 5.0) ** 2
    assert cell_sigma_m(S21B, f, 4, 0.1, 4.0) == pytest.approx(point_sigma_m(S21B, f, 4.0) / math.sqrt(n))
    assert cell_sigma_m(S21B, f, 4, 0.01, 4.0) == pytest.approx(point_sigma_m(S21B, f, 4.0))


def test_the_cart_depth_is_the_median_of_the_points_inside_the_rim():
    corners = np.array([[0.0, 0.0, 3.0], [6.0, 0.0, 3.0], [6.0, 3.0, 3.0], [0.0, 3.0, 3.0]])
    level = np.array([[1.0, 1.0, 2.0], [5.0, 2.0, 2.0], [7.0, 1.0, 0.0], [np.nan] * 3, [3.0, 2.9, 2.0]])
    record = np.zeros((5, 4), np.float32)
    record[:, 2] = [4.0, 5.0, 9.0, 1.0, 6.0]
    assert cart_depth_m(record, level, corners) == pytest.approx(5.0)
    assert cart_depth_m(record, level, corners[::-1]) == pytest.approx(5.0), "either winding"
    assert math.isnan(cart_depth_m(record[2:3], level[2:3], corners))


@pytest.mark.gl
def test_a_head_too_high_for_the_target_stops_safe_naming_its_error(tmp_path):
    """The S21B head 1.5 m higher sees the grain at 5.5 m: a cell's expected 1-sigma there (4.6 cm) is more than
    the 2.5 cm the 5 cm overfill tolerance allows, so perception publishes no height map, the auger never starts
    and the run stops safe; the summary names the figure."""
    from cosim.runtime.launcher import launch

    res = launch(load_scenario(VARIANTS / "stereo_spout_high.yaml", extra={"duration_s": 2.0}), tmp_path / "high",
                 console_log=False)
    s = res.summary
    assert res.completed and s["outcome"]["status"] == "stopped_safe", s["outcome"]
    assert s["outcome"]["auger_on_s"] == 0.0 and s["outcome"]["cart_found_frames"] > 0
    fit = s["perception"]["fitness"]
    assert fit["unfit_frames"] == fit["frames_at_cart"] > 0
    assert 0.035 < fit["height_sigma_m"] < 0.06 and 5.0 < fit["depth_m"] < 6.0, fit
    assert f"{100 * fit['height_sigma_m']:.1f} cm at {fit['depth_m']:.1f} m" in fit["reason"]


@pytest.mark.gl
def test_the_oak_d_on_the_spout_finds_the_cart_and_stops_safe_naming_its_error(tmp_path):
    """From the spout the OAK-D sees one end of the cart and no side rim: the rim finder alone never found it; the
    rim fitted from Machine Sync's pose finds it in every frame, and its expected error there (about 5.5 cm at
    4.0 m) stops the run safe before the auger starts."""
    from cosim.runtime.launcher import launch

    res = launch(load_scenario(VARIANTS / "stereo_spout_oak_d.yaml", extra={"duration_s": 1.0}), tmp_path / "oak",
                 console_log=False)
    s = res.summary
    out, fit = s["outcome"], s["perception"]["fitness"]
    assert res.completed and out["status"] == "stopped_safe" and out["auger_on_s"] == 0.0, out
    assert out["cart_found_frames"] == out["perception_frames"] > 0
    assert fit["unfit_frames"] == fit["frames_at_cart"] > 0 and 0.04 < fit["height_sigma_m"] < 0.07, fit
    assert f"{100 * fit['height_sigma_m']:.1f} cm at {fit['depth_m']:.1f} m" in out["reason"]


@pytest.mark.gl
def test_bm_on_the_spout_finds_the_cart_every_frame_and_starts_the_auger(tmp_path):
    """StereoBM on the packaged head: about half the pixels valid, the cart found in every frame (the rim fit
    where the rim finder has no answer), fit for the target, the auger on."""
    from cosim.runtime.launcher import launch

    res = launch(load_scenario(VARIANTS / "stereo_spout_bm.yaml", extra={"duration_s": 1.5}), tmp_path / "bm",
                 console_log=False)
    s = res.summary
    out, fit = s["outcome"], s["perception"]["fitness"]
    assert res.completed and out["cart_found_frames"] == out["perception_frames"] > 0, out
    assert fit["unfit_frames"] == 0 and out["auger_on_s"] > 0.0 and s["spill"]["mass_kg"] == 0.0


@pytest.mark.gl
def test_bm_where_sgbm_would_fill_stops_safe_naming_the_matchers_figure(tmp_path):
    """The BM head 0.3 m higher on the spout: its expected error at the cart with StereoBM's disparity error is more
    than the target allows, and the run stops safe naming StereoBM's figure; SGBM's at the same depth would pass."""
    from cosim.runtime.launcher import launch

    s = load_scenario(VARIANTS / "stereo_spout_bm.yaml", extra={"duration_s": 1.0},
                      overrides=["sensors.spout.mount.xyz_m=[-2.0, 7.45, 6.3]"])
    res = launch(s, tmp_path / "bm_high", console_log=False)
    out, fit = res.summary["outcome"], res.summary["perception"]["fitness"]
    assert res.completed and out["status"] == "stopped_safe" and out["auger_on_s"] == 0.0, out
    assert fit["unfit_frames"] == fit["frames_at_cart"] > 0, fit
    assert "spout: StereoBM, disparity 1-sigma 0.34 px" in out["reason"], out["reason"]
    sgbm = s.sensor_set["spout"].model_copy(update={"matcher": "sgbm"})
    f = sgbm.focal_px
    assert 2.0 * cell_sigma_m(sgbm, f, 4, s.controller.grid_cell_m, fit["depth_m"]) <= 0.05 < 2.0 * fit["height_sigma_m"]


@pytest.mark.gl
@pytest.mark.slow
@pytest.mark.parametrize("name", [p.stem for p in sorted(VARIANTS.glob("*.yaml"))])
def test_a_held_out_camera_fills_or_stops_safe_saying_why(tmp_path, name):
    """Whole runs with perception feedback: filled (no spill, at most 5 cm over) or stopped safe, never
    job_failed; stopped safe only with a reason that names the sensor's figure or a cart that is not in view."""
    from cosim.runtime.launcher import launch

    res = launch(load_scenario(VARIANTS / f"{name}.yaml"), tmp_path / name, console_log=False)
    s = res.summary
    out = s["outcome"]
    assert out["status"] in ("filled", "stopped_safe"), out
    if out["status"] == "filled":
        assert s["spill"]["mass_kg"] == 0.0 and s["fill"]["max_overfill_m"] <= MAX_OVERFILL_M
    else:
        assert s["perception"]["fitness"]["reason"] is not None, (out, s["perception"]["fitness"])
