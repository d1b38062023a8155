"""Shared-memory blocks written by the perception participant (CONTRACTS.md, "Blocks").

* ``perc_state`` struct: frame time, cart boundary (rim corners in the sensor frame, the cart pose), impact
  (cart grid frame), coverage, stage timings and per-frame accuracy against an exact ray cast (NaN on frames
  where accuracy is not evaluated). Every field is a ``timeseries.csv`` column ``perc_state.<field>``.
* ``heightmap_perceived`` (nxc, nyc) float32: grain height m above the cart floor on the controller's grid
  (``controller.grid_cell_m``), NaN where there is no valid return (or no cart).
* ``lidar_points`` (N, 4) float32: x, y, z (sensor frame, m), range (m); NaN rows for invalid beams.
"""
from __future__ import annotations

from cosim.scenario.config import Scenario
from cosim.world.patterns import beam_table
from shm_schema import ArrayBlock, Block, Field, StructBlock

__all__ = ["WRITER", "STATE_BLOCK", "HEIGHTS_BLOCK", "POINTS_BLOCK", "RANGE_BANDS_M", "band_name",
           "state_fields", "declare_blocks", "ACCURACY_FIELDS"]

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


def declare_blocks(scenario: Scenario) -> list[Block]:
    """The perception blocks for ``scenario`` (empty when the scenario runs no perception)."""
    if not scenario.needs_perception:
        return []
    nxc, nyc = scenario.cart.grid_shape(scenario.controller.grid_cell_m)
    n = beam_table(scenario.sensor.pattern)[0].shape[0]
    return [
        StructBlock(STATE_BLOCK, WRITER, state_fields(), doc="perception outputs and accuracy per frame"),
        ArrayBlock(HEIGHTS_BLOCK, WRITER, "f4", (nxc, nyc), unit="m",
                   doc="grain height above the cart floor, controller grid, cart grid frame; NaN no return"),
        ArrayBlock(POINTS_BLOCK, WRITER, "f4", (n, 4), unit="m",
                   doc="LiDAR points x, y, z (sensor frame) and range; NaN rows invalid"),
    ]
