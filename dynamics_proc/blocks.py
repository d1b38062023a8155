"""Shared-memory blocks written by the dynamics participant (CONTRACTS.md, "Blocks").

* ``dyn_state`` struct: poses, spout, stream and impact, the Fig 9 signals, volumes, section fullness; every
  field becomes a ``timeseries.csv`` column ``dyn_state.<field>``, so names carry units.
* ``stream`` (64, 4) float32: rows [x, y, z, radius] (world, m) from the spout to the impact point.
* ``heightmap_truth`` (nx, ny) float32: grain height m above the cart floor, grain grid, cart grid frame.
"""
from __future__ import annotations

from cosim.scenario.config import Scenario
from dynamics_proc.grain.auger import STREAM_ROWS
from dynamics_proc.grain.fill import GrainGrid
from shm_schema import ArrayBlock, Block, Field, StructBlock

__all__ = ["WRITER", "STATE_FIELDS", "SECTION_FIELD", "state_fields", "declare_blocks"]

WRITER = "dynamics"
#: dyn_state field name of section k's fullness (k = 1..N)
SECTION_FIELD = "section{k}_fullness"

#: (name, unit, dtype, doc) of every dyn_state field except the per-section ones
STATE_FIELDS: tuple[tuple[str, str, str, str], ...] = (
    ("t_s", "s", "f8", "simulation time of this state"),
    ("frame", "", "i8", "frame id of this state"),
    ("combine_x_m", "m", "f8", "combine body origin, world"),
    ("combine_y_m", "m", "f8", ""),
    ("combine_yaw_rad", "rad", "f8", ""),
    ("combine_z_m", "m", "f8", "combine body origin height on the terrain, world (0 on flat ground)"),
    ("combine_roll_rad", "rad", "f8", "combine roll on the terrain (R = Rz(yaw) Ry(pitch) Rx(roll))"),
    ("combine_pitch_rad", "rad", "f8", "combine pitch on the terrain (positive: nose down)"),
    ("combine_speed_mps", "m/s", "f8", ""),
    ("combine_yaw_rate_radps", "rad/s", "f8", "combine's yaw rate (its path's curvature x speed)"),
    ("tractor_x_m", "m", "f8", "tractor body origin, world"),
    ("tractor_y_m", "m", "f8", ""),
    ("tractor_yaw_rad", "rad", "f8", ""),
    ("tractor_z_m", "m", "f8", "tractor body origin height on the terrain, world (0 on flat ground)"),
    ("tractor_roll_rad", "rad", "f8", "tractor roll on the terrain (R = Rz(yaw) Ry(pitch) Rx(roll))"),
    ("tractor_pitch_rad", "rad", "f8", "tractor pitch on the terrain (positive: nose down)"),
    ("tractor_speed_mps", "m/s", "f8", "drivetrain lag state"),
    ("tractor_steer_rad", "rad", "f8", "steering lag state"),
    ("cart_x_m", "m", "f8", "cart body origin (interior centre, on the ground), world"),
    ("cart_y_m", "m", "f8", ""),
    ("cart_yaw_rad", "rad", "f8", ""),
    ("cart_z_m", "m", "f8", "cart body origin height on the terrain, world (0 on flat ground)"),
    ("cart_roll_rad", "rad", "f8", "cart roll on the terrain (R = Rz(yaw) Ry(pitch) Rx(roll))"),
    ("cart_pitch_rad", "rad", "f8", "cart pitch on the terrain (positive: nose down)"),
    ("spout_x_m", "m", "f8", "auger spout, world"),
    ("spout_y_m", "m", "f8", ""),
    ("spout_z_m", "m", "f8", ""),
    ("auger_on", "", "i8", "auger command (0/1)"),
    ("flow_level", "", "f8", "flow as a fraction of the nominal flow (spool-up / run-out)"),
    ("flow_m3ps", "m^3/s", "f8", "grain flow leaving the spout"),
    ("flow_factor", "", "f8", "yield variation and start surge of the flow (1: none)"),
    ("impact_x_m", "m", "f8", "true impact point of the stream, world"),
    ("impact_y_m", "m", "f8", ""),
    ("impact_z_m", "m", "f8", ""),
    ("impact_valid", "", "i8", "1 while grain is in the air"),
    ("impact_surface", "", "i8", "0 none, 1 grain/floor, 2 wall or rim, 3 ground"),
    ("impact_gx_m", "m", "f8", "true impact point, cart grid frame"),
    ("impact_gy_m", "m", "f8", ""),
    ("impact_gz_m", "m", "f8", ""),
    ("stream_points", "", "i8", "valid rows of the stream block"),
    ("desired_auger_x_m", "m", "f8", "Fig 9: desired auger location, cart grid x"),
    ("control_effort_m", "m", "f8", "Fig 9: continuous control effort, cart grid x"),
    ("nudge_m", "m", "f8", "Fig 9: nudge (actuating) signal, cart grid x"),
    ("actual_auger_x_m", "m", "f8", "Fig 9: actual auger (spout) location, cart grid x"),
    ("actual_auger_y_m", "m", "f8", "spout location, cart grid y"),
    ("nudge_cmd", "", "i8", "nudge sent this frame: -1, 0, +1"),
    ("nudge_count", "", "i8", "nudges sent so far"),
    ("setpoint_long_m", "m", "f8", "Machine Sync setpoint: cart ahead of the combine"),
    ("setpoint_lat_m", "m", "f8", "Machine Sync setpoint: cart left of the combine"),
    ("offset_long_err_m", "m", "f8", "actual minus setpoint cart offset, combine axes"),
    ("offset_lat_err_m", "m", "f8", ""),
    ("target_section", "", "i8", "section being filled, 1..N, 0 none"),
    ("all_full", "", "i8", "controller: every section reached its target"),
    ("measurement_seen", "", "i8", "controller: a height-map measurement has arrived"),
    ("control_bias_m", "m", "f8", "controller: learnt steady-state auger offset"),
    ("target_fill_m", "m", "f8", "controller: target grain height (a run-time input, dynamics_proc.inputs)"),
    ("control_mode", "", "i8", "controller: 0 measured, 1 dead reckoning, 2 holding (dynamics_proc.control.coping)"),
    ("hold_reason", "", "i8", "controller: why it holds (cosim.scenario.config.holds.HOLD_REASONS), 0 not holding"),
    ("estimate_sigma_m", "m", "f8", "controller: stated 1-sigma of its estimate of the target section"),
    ("full_lead_m", "m", "f8", "controller: lead added to the target section's level (rise rate x lead)"),
    ("lateral_feedforward_m", "m", "f8", "controller: correction of the lateral setpoint ahead of a turn"),
    ("delivered_m3", "m^3", "f8", "cumulative volume delivered by the auger"),
    ("in_cart_m3", "m^3", "f8", "grain in the cart minus the initial grain (height-map sum)"),
    ("spilled_m3", "m^3", "f8", "cumulative spill (outside the cart or over a wall top)"),
    ("spilled_outside_m3", "m^3", "f8", "part of the spill that landed outside the interior"),
    ("cart_grain_m3", "m^3", "f8", "grain in the cart"),
    ("peak_height_m", "m", "f8", "highest grain cell above the floor"),
    ("gnss_error_long_m", "m", "f8", "tractor's GNSS error relative to the combine's, along the combine"),
    ("gnss_error_lat_m", "m", "f8", "... across the combine (Machine Sync steers on it)"),
    ("tractor_slip", "", "f8", "tractor wheel slip (ground speed = wheel speed x (1 - slip))"),
)


def state_fields(sections: int) -> tuple[Field, ...]:
    """Every ``dyn_state`` field, the per-section fullness (estimated height / target, 1 = full) last."""
    fields = [Field(n, unit=u, dtype=d, doc=doc) for n, u, d, doc in STATE_FIELDS]
    fields += [Field(SECTION_FIELD.format(k=k), unit="", dtype="f8",
                     doc=f"section {k}: controller's estimated peak / target (NaN unknown)")
               for k in range(1, sections + 1)]
    return tuple(fields)


def declare_blocks(scenario: Scenario) -> list[Block]:
    """The dynamics blocks for ``scenario``: dyn_state, stream, heightmap_truth."""
    g = GrainGrid.from_scenario(scenario)
    return [
        StructBlock("dyn_state", WRITER, state_fields(scenario.controller.sections),
                    doc="ground truth and controller signals after each frame"),
        ArrayBlock("stream", WRITER, "f4", (STREAM_ROWS, 4), unit="m",
                   doc="stream centreline rows [x, y, z, radius], world; rows >= stream_points unused"),
        ArrayBlock("heightmap_truth", WRITER, "f4", (g.nx, g.ny), unit="m",
                   doc="grain height above the cart floor, grain grid, cart grid frame"),
    ]
