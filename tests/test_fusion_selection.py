"""Which sensors enter the fusion (perception_proc.selection, docs/cameras.md): a camera unfit for the target is
left out while a fit sensor is left, with its figure logged once and in the summary; alone it stops the run safe."""
from __future__ import annotations

import logging

import numpy as np
import pytest

from cosim.runtime.inprocess import simulate
from cosim.scenario.loader import load_scenario_text
from cosim.world.sensors import camera_pinhole, points_stride
from perception_proc.cameras.expected import cell_sigma_m
from perception_proc.selection import CameraFit, FusionSelection, judge

TOL = 0.05
#: a LiDAR on the mast and a time-of-flight camera 8.5 m up on the spout: it sees the grain at about 6.5 m, where
#: a cell's expected 1-sigma (about 5 cm) is twice what the 5 cm overfill tolerance allows (2.5 cm)
LIDAR_AND_FAR_TOF = """format_version: 1
name: lidar_and_far_tof
renderer: mock
duration_s: 1.0
feedback: perception
grain:
  initial_fill_m: 1.0
controller:
  target_fill_m: 1.9
sensors:
  mast:
    kind: lidar
    method: beam_native
  tof:
    kind: depth_camera
    profile: tof_kinect_class
    range_max_m: 10.0
    every_frames: 3
    points_stride: 3
    mount: {parent: combine, xyz_m: [-2.0, 7.45, 8.5], rpy_deg: [0.0, 90.0, -90.0]}
"""
FAR_TOF_ALONE = LIDAR_AND_FAR_TOF.replace("""  mast:
    kind: lidar
    method: beam_native
""", "")


class _Frame:
    def __init__(self, name: str):
        self.name = name


def test_an_unfit_camera_is_left_out_while_a_lidar_is_fused_and_logged_once(caplog):
    sel = FusionSelection(has_lidar=True)
    cams = [(_Frame("a"), None), (_Frame("b"), None)]
    unfit = judge({"a": (0.03, 6.0), "b": (0.01, 3.0)}, TOL)
    assert unfit["a"].unfit and not unfit["b"].unfit
    with caplog.at_level(logging.INFO, logger="cosim.perception"):
        assert sel.update(unfit) is True, "a was fused this frame: perceive it again without a"
        assert [f.name for f, _ in sel.fused(cams)] == ["b"]
        assert sel.update(unfit) is False, "already left out"
        assert sel.update({"b": CameraFit(0.01, 3.0, TOL)}) is False, "a not seeing the cart keeps its verdict"
        assert list(sel.dropped) == ["a"] and "3.0 cm at 6.0 m" in sel.dropped["a"]
        sel.update(judge({"a": (0.02, 4.0)}, TOL))
        assert not sel.dropped, "fit again: fused again"
        sel.update(unfit)
    warnings = [r for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 1 and "camera a" in warnings[0].getMessage(), "the reason is logged once"


def test_without_a_fit_sensor_nothing_is_left_out():
    """Cameras alone, every one that sees the cart unfit: none is left out (the height map is withheld)."""
    sel = FusionSelection(has_lidar=False)
    fits = judge({"a": (0.03, 6.0), "b": (0.04, 7.0)}, TOL)
    assert not sel.fit_left(fits) and sel.update(fits) is False and not sel.dropped
    fits = judge({"a": (0.03, 6.0), "b": (0.01, 3.0)}, TOL)
    assert sel.update(fits) is True and list(sel.dropped) == ["a"]


@pytest.fixture(scope="module")
def fused_run():
    s = load_scenario_text(LIDAR_AND_FAR_TOF, check_world=True)
    return s, simulate(s).recorder.series()


def test_a_lidar_fills_beside_an_unfit_camera_whose_figure_the_summary_names(fused_run):
    from perception_proc.summary import camera_fitness, fitness

    s, ser = fused_run
    assert np.all(ser["perc_state.cart_valid"] == 1)
    assert np.all(ser["perc_state.sensor_unfit"] == 0) and np.all(ser["perc_state.coverage"] > 0.5)
    assert np.all(ser["perc_state.sensors_dropped"] == 1) and np.all(ser["sensor_tof.fused"] == 0)
    assert np.all(ser["sensor_mast.fused"] == 1) and np.all(ser["sensor_tof.unfit"] == 1)
    assert np.any(ser["dyn_state.auger_on"] == 1), "the LiDAR's map starts the auger"
    sigma = ser["sensor_tof.cart_sigma_m"]
    # the closed form of a cell's sigma at the depth it sees the cart, and unfit (over 2.5 cm) by it
    cam = s.cameras["tof"]
    expect = [cell_sigma_m(cam, camera_pinhole(cam, s).f, points_stride(cam, s), s.controller.grid_cell_m, z)
              for z in ser["sensor_tof.cart_depth_m"]]
    np.testing.assert_allclose(sigma, expect, rtol=1e-9)
    assert np.all(sigma > 0.025), sigma
    assert fitness(s, ser)["reason"] is None
    fit = camera_fitness(s, ser)["tof"]
    assert fit["left_out_frames"] == fit["frames_at_cart"] == len(sigma)
    figure = f"{100 * fit['height_sigma_m']:.1f} cm at {fit['depth_m']:.1f} m"
    assert fit["reason"].startswith("camera tof: ") and figure in fit["reason"]


def test_the_same_camera_alone_stops_safe_naming_its_figure():
    from perception_proc.summary import camera_fitness, fitness

    s = load_scenario_text(FAR_TOF_ALONE, overrides=["duration_s=0.5"], check_world=True)
    ser = simulate(s).recorder.series()
    assert np.all(ser["perc_state.cart_valid"] == 1) and np.all(ser["perc_state.sensor_unfit"] == 1)
    assert np.all(ser["perc_state.coverage"] == 0.0) and not np.any(ser["dyn_state.auger_on"] == 1)
    fit = fitness(s, ser)
    assert fit["unfit_frames"] == fit["frames_at_cart"] > 0
    assert f"{100 * fit['height_sigma_m']:.1f} cm at {fit['depth_m']:.1f} m" in fit["reason"]
    assert camera_fitness(s, ser)["tof"]["left_out_frames"] == 0


def test_a_camera_that_never_sees_the_cart_is_named_and_the_lidar_fills():
    """The camera turned to look ahead of the combine (the scenario check refuses such a mount at the start; a
    camera can lose the cart later): the LiDAR finds the cart and maps it alone; the summary says the camera never
    saw it."""
    from perception_proc.summary import camera_fitness

    s = load_scenario_text(LIDAR_AND_FAR_TOF, check_world=False, overrides=[
        "duration_s=0.5", "sensors.tof.mount={parent: combine, xyz_m: [5.0, 0.0, 4.0], rpy_deg: [0.0, 40.0, 0.0]}"])
    ser = simulate(s).recorder.series()
    assert np.all(ser["perc_state.cart_valid"] == 1) and np.all(ser["perc_state.coverage"] > 0.5)
    assert np.all(ser["perc_state.sensor_unfit"] == 0) and np.all(ser["sensor_tof.points"] > 0)
    fit = camera_fitness(s, ser)["tof"]
    assert fit["frames_at_cart"] == 0 and fit["reason"].startswith("camera tof: never saw the found cart")
