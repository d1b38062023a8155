"""Shared-memory blocks written by the perception participant (CONTRACTS.md, "Blocks").

* ``perc_state`` struct: frame time, cart boundary (rim corners in the sensor frame, the cart pose), impact
  (cart grid frame), coverage, stage timings and per-frame accuracy against an exact ray cast (NaN on frames
  where accuracy is not evaluated). Every field is a ``timeseries.csv`` column ``perc_state.<field>``.
* ``heightmap_perceived`` (nxc, nyc) float32: grain height m above the cart floor on the controller's grid
  (``controller.grid_cell_m``), NaN where there is no valid return (or no cart).
* ``lidar_points`` (N, 4) float32: x, y, z (sensor frame, m), range (m); NaN rows for invalid beams (only
  with a LiDAR);
* per depth-giving camera (docs/cameras.md): ``cam_<name>_measured`` (H, W) float32, the camera's measured
  planar depth m (the depth camera's model, the stereo matcher's), NaN invalid; ``cam_<name>_points`` (M, 4)
  float32, its strided pixels back-projected, x y z (camera frame) and range m, NaN rows invalid;
* with ``sensors:``, per depth-giving sensor, the struct ``sensor_<name>``: the share of valid data, the
  model's time, and on evaluated frames its depth error against the exact ray cast and the error of the
  height map it alone gives (:data:`SENSOR_FIELDS`).
"""
from __future__ import annotations

from cosim.scenario.config import Scenario
from cosim.scenario.config.cameras import DEPTH_KINDS
from cosim.world.patterns import beam_table
from cosim.world.sensors import camera_block, camera_pinhole, points_stride
from shm_schema import ArrayBlock, Block, Field, StructBlock

__all__ = ["WRITER", "STATE_BLOCK", "HEIGHTS_BLOCK", "POINTS_BLOCK", "RANGE_BANDS_M", "band_name",
           "state_fields", "declare_blocks", "ACCURACY_FIELDS", "SENSOR_FIELDS", "sensor_state_block",
           "camera_output_blocks"]

WRITER = "perception"
STATE_BLOCK = "perc_state"
HEIGHTS_BLOCK = "heightmap_perceived"
POINTS_BLOCK = "lidar_points"

#: distance bands (m, [lo, hi)) of the range-error table; the working range is 2-15 m
RANGE_BANDS_M: tuple[tuple[float, float], ...] = ((0.0, 2.0), (2.0, 5.0), (5.0, 10.0), (10.0, 15.0),
                                                   (15.0, 40.0), (40.0, 1000.0))


def band_name(lo: float, hi: float) -> str:
    """Field stem of a band, e.g. ``b2_5`` for [2, 5) m."""
    return f"b{lo:g}_{hi:g}".replace(".", "p")


_BASE: tuple[tuple[str, str, str, str], ...] = (
    ("t_s", "s", "f8", "simulation time of the state these images show (dyn_state.t_s)"),
    ("frame", "", "i8", "frame id of this output"),
    ("valid_beams", "", "i8", "beams with a valid return this frame (after noise and limits)"),
    ("cart_valid", "", "i8", "1 when the cart boundary was found"),
    ("cart_partial", "", "i8", "1 when an end of the cart was out of view and anchored from its known size"),
    *((f"corner{k}_{a}_m", "m", "f8", f"rim corner {k} (grid order), sensor frame" if a == "x" else "")
      for k in range(4) for a in "xyz"),
    ("cart_x_m", "m", "f8", "perceived cart body origin, world (from the combine's GNSS pose)"),
    ("cart_y_m", "m", "f8", ""),
    ("cart_yaw_rad", "rad", "f8", "perceived cart heading, world"),
    ("impact_valid", "", "i8", "1 when the stream's impact on the grain was found"),
    ("impact_gx_m", "m", "f8", "perceived impact point, cart grid frame"),
    ("impact_gy_m", "m", "f8", ""),
    ("impact_gz_m", "m", "f8", ""),
    ("coverage", "", "f8", "fraction of controller cells with a perceived height"),
    ("height_sigma_m", "m", "f8", "the depth cameras' expected 1-sigma of a cell's height at the cart (largest; NaN: "
     "no camera sees it)"),
    ("height_sigma_depth_m", "m", "f8", "the planar depth at which that camera sees the cart"),
    ("sensor_unfit", "", "i8", "1 when a camera's sigma exceeds what outcome.overfill_tolerance_m allows and no fit "
     "sensor is left: no height map is published and the controller holds"),
    ("sensors_dropped", "", "i8", "cameras left out of the fusion as unfit for the target (a fit sensor is left)"),
    ("lidar_ms", "ms", "f8", "decode, resample, noise"),
    ("cart_ms", "ms", "f8", "cart boundary"),
    ("heightmap_ms", "ms", "f8", "height map"),
    ("impact_ms", "ms", "f8", "impact location"),
    ("perception_ms", "ms", "f8", "whole step"),
    ("accuracy_ms", "ms", "f8", "accuracy evaluation (exact ray cast), NaN when not evaluated"),
)

#: accuracy fields (all NaN on frames without an evaluation); range errors are of the noise-free ranges
ACCURACY_FIELDS: tuple[tuple[str, str, str, str], ...] = (
    ("acc_evaluated", "", "i8", "1 on frames with an accuracy evaluation"),
    ("range_beams", "", "f8", "beams valid in both the LiDAR and the exact cast"),
    ("range_err_mean_m", "m", "f8", "mean |range - exact range|, all distances"),
    ("range_err_median_m", "m", "f8", "median |range error|"),
    ("range_err_p99_m", "m", "f8", "99th percentile |range error|"),
    ("range_err_max_m", "m", "f8", "largest |range error|"),
    ("frac_above_5cm", "", "f8", "share of beams with |range error| > 5 cm"),
    ("range_err_mean_2_15_m", "m", "f8", "mean |range error| inside the 2-15 m working range"),
    ("frac_above_5cm_2_15", "", "f8", "share above 5 cm inside the 2-15 m working range"),
    ("range_err_p99_2_15_m", "m", "f8", "99th percentile |range error| inside the 2-15 m working range"),
    ("beam_missing_frac", "", "f8", "share of beams with an exact hit in range but no LiDAR return"),
    ("beam_spurious_frac", "", "f8", "share of LiDAR returns where the exact cast has none in range"),
    *(item for lo, hi in RANGE_BANDS_M for item in (
        (f"rerr_{band_name(lo, hi)}_n", "", "f8", f"beams in [{lo:g}, {hi:g}) m"),
        (f"rerr_{band_name(lo, hi)}_mean_m", "m", "f8", ""),
        (f"rerr_{band_name(lo, hi)}_p99_m", "m", "f8", ""),
        (f"rerr_{band_name(lo, hi)}_above5_frac", "", "f8", ""),
    )),
    ("heightmap_rmse_m", "m", "f8", "RMSE of perceived vs true heights over cells with both"),
    ("heightmap_bias_m", "m", "f8", "mean perceived minus true height over cells with both"),
    ("corner_error_m", "m", "f8", "mean distance of the 4 rim corners from the truth"),
    ("impact_error_m", "m", "f8", "horizontal distance of the impact from the truth, cart grid frame"),
)


def state_fields() -> tuple[Field, ...]:
    """Every ``perc_state`` field."""
    return tuple(Field(n, unit=u, dtype=d, doc=doc) for n, u, d, doc in _BASE + ACCURACY_FIELDS)


#: the fields of a sensor's own status struct ``sensor_<name>`` (named sensors only; NaN where not evaluated)
SENSOR_FIELDS: tuple[tuple[str, str, str, str], ...] = (
    ("t_s", "s", "f8", "simulation time of the state the sensor's data show"),
    ("frame", "", "i8", "ring frame of the sensor's latest data"),
    ("valid_fraction", "", "f8", "share of the sensor's pixels (beams) with a valid depth (range)"),
    ("points", "", "i8", "valid points the sensor gave the built-in algorithm"),
    ("measure_ms", "ms", "f8", "the sensor's model: noise, or the stereo matcher"),
    ("acc_evaluated", "", "i8", "1 on frames compared with the exact ray cast"),
    ("depth_pixels", "", "f8", "pixels (beams) valid in both the sensor and the exact cast, working range"),
    ("depth_err_mean_m", "m", "f8", "mean |depth - exact depth| (range for the LiDAR), working range"),
    ("depth_err_median_m", "m", "f8", "median |depth error|, working range"),
    ("depth_err_p99_m", "m", "f8", "99th percentile |depth error|, working range"),
    ("frac_above_5cm", "", "f8", "share of |depth error| > 5 cm, working range"),
    ("coverage", "", "f8", "share of pixels with an exact hit in the working range that have a valid depth"),
    ("spurious_frac", "", "f8", "share of valid depths where the exact cast has none in range"),
    ("fill_rel_err", "", "f8", "mean |h - h_true| / h_true over the cells this sensor alone maps"),
    ("fill_bias_m", "m", "f8", "mean h - h_true over those cells"),
    ("fill_cells", "", "f8", "controller cells this sensor alone maps"),
    ("cart_sigma_m", "m", "f8", "a camera's expected 1-sigma of a cell's height at the found cart (NaN: a LiDAR, or "
     "the camera does not see it)"),
    ("cart_depth_m", "m", "f8", "the planar depth at which the camera sees the cart"),
    ("unfit", "", "i8", "1 when that sigma exceeds what outcome.overfill_tolerance_m allows"),
    ("fused", "", "i8", "1 when the sensor's points entered this frame's fusion (0: left out as unfit)"),
)


def sensor_state_block(name: str) -> str:
    """The status struct of named sensor ``name``: ``sensor_<name>``."""
    return f"sensor_{name}"


def camera_output_blocks(scenario: Scenario, name: str) -> dict[str, tuple[str, tuple[int, ...]]]:
    """The blocks perception writes for depth-giving camera ``name``: part -> (block, shape): ``measured``
    (H, W) float32 the sensor's planar depth m (NaN invalid), ``points`` (M, 4) float32 its strided pixels
    back-projected, x y z (camera frame) and range m (NaN rows invalid)."""
    cam = scenario.cameras[name]
    pin = camera_pinhole(cam, scenario)
    s = points_stride(cam, scenario)
    rows, cols = len(range(s // 2, pin.height, s)), len(range(s // 2, pin.width, s))
    return {"measured": (camera_block(name, "measured"), (pin.height, pin.width)),
            "points": (camera_block(name, "points"), (rows * cols, 4))}


def declare_blocks(scenario: Scenario) -> list[Block]:
    """The perception blocks for ``scenario`` (empty when the scenario runs no perception)."""
    if not scenario.needs_perception:
        return []
    nxc, nyc = scenario.cart.grid_shape(scenario.controller.grid_cell_m)
    blocks: list[Block] = [
        StructBlock(STATE_BLOCK, WRITER, state_fields(), doc="perception outputs and accuracy per frame"),
        ArrayBlock(HEIGHTS_BLOCK, WRITER, "f4", (nxc, nyc), unit="m",
                   doc="grain height above the cart floor, controller grid, cart grid frame; NaN no return"),
    ]
    if scenario.lidar is not None:
        n = beam_table(scenario.lidar.pattern)[0].shape[0]
        blocks.append(ArrayBlock(POINTS_BLOCK, WRITER, "f4", (n, 4), unit="m",
                                 doc="LiDAR points x, y, z (sensor frame) and range; NaN rows invalid"))
    for name, cam in scenario.cameras.items():
        if cam.kind not in DEPTH_KINDS:
            continue
        out = camera_output_blocks(scenario, name)
        blocks.append(ArrayBlock(out["measured"][0], WRITER, "f4", out["measured"][1], unit="m",
                                 doc=f"camera {name}: measured planar depth, NaN invalid"))
        blocks.append(ArrayBlock(out["points"][0], WRITER, "f4", out["points"][1], unit="m",
                                 doc=f"camera {name}: points x, y, z (camera frame) and range; NaN rows invalid"))
    if scenario.sensors:
        for name in scenario.depth_sensors:
            blocks.append(StructBlock(sensor_state_block(name), WRITER,
                                      tuple(Field(n, unit=u, dtype=d, doc=doc) for n, u, d, doc in SENSOR_FIELDS),
                                      doc=f"sensor {name}: data validity, accuracy, own height map"))
    return blocks
