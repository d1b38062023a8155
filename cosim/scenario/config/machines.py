"""Scenario sections for the machines and the grain: crop, combine, auger, tractor, cart, Machine Sync.

Owned by dynamics_proc. Fields used by other packages (cart geometry, auger geometry, entity
dimensions, mesh files) keep their names; others may be added. Defaults describe the paper's machines:
S660-class combine, 8345R-class tractor, Brandt 1020XR-class cart, corn.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Literal

from pydantic import Field, field_validator

from .base import Model, NonNegFloat, PosFloat
from .field import GaussMarkov, ProfilePoint, Slip, increasing_times

__all__ = ["Crop", "Combine", "Auger", "Tractor", "Cart", "MachineSync", "CROP_PRESETS"]

#: crop name -> (bulk density kg/m^3, angle of repose deg)
CROP_PRESETS: dict[str, tuple[float, float]] = {
    "corn": (720.0, 23.0),
    "soybeans": (772.0, 25.0),
    "wheat": (772.0, 25.0),
}


class Crop(Model):
    """Grain being offloaded. Density and repose default to the named crop's preset."""

    name: Literal["corn", "soybeans", "wheat"] = "corn"
    """corn, soybeans or wheat: sets the default density and angle of repose."""
    density_kgpm3: PosFloat | None = None
    """Bulk density, kg/m^3; unset: the crop's preset."""
    repose_deg: float | None = Field(default=None, gt=0.0, lt=60.0)
    """Angle of repose of the heap, deg (0-60); unset: the crop's preset."""

    @property
    def density(self) -> float:
        """Bulk density, kg/m^3."""
        return self.density_kgpm3 if self.density_kgpm3 is not None else CROP_PRESETS[self.name][0]

    @property
    def repose_rad(self) -> float:
        """Angle of repose, rad."""
        deg = self.repose_deg if self.repose_deg is not None else CROP_PRESETS[self.name][1]
        return math.radians(deg)


class Combine(Model):
    """Combine harvester: path, speed and the box dimensions used to draw it.

    ``profile`` (docs/field.md): speed and curvature against time (slow-downs, stop-and-go, headland turns),
    linear between its points; when given it replaces ``speed_mps`` and ``path``."""

    speed_mps: NonNegFloat = 2.0
    """Ground speed along the path, m/s."""
    path: Literal["straight", "arc"] = "straight"
    """straight or arc (of path_radius_m, turning left)."""
    path_radius_m: PosFloat = 400.0
    """Radius of the arc path, m."""
    profile: tuple[ProfilePoint, ...] = ()
    """Speed and path curvature against time, linear between points; replaces speed_mps and path when given."""
    start_xy_m: tuple[float, float] = (0.0, 0.0)
    """Start position of the combine body origin in the world frame, m."""
    heading_deg: float = 0.0
    """Start heading, deg from the world x axis towards y."""
    length_m: PosFloat = 8.5
    """Length of the drawn body box, m."""
    width_m: PosFloat = 3.5
    """Width of the drawn body box, m."""
    height_m: PosFloat = 3.9
    """Height of the drawn body box, m."""
    header_width_m: PosFloat = 7.6
    """Width of the header (cutting platform), m."""
    mesh_file: Path | None = None
    """A mesh (any format trimesh reads) drawn instead of the boxes, relative to the scenario file."""

    @field_validator("profile")
    @classmethod
    def _profile_in_order(cls, v: tuple[ProfilePoint, ...]) -> tuple[ProfilePoint, ...]:
        return increasing_times(v)


class Auger(Model):
    """Unloading auger on the combine's left side. Geometry in the combine body frame.

    Field conditions (docs/field.md): ``flow_variation``, the yield-driven relative variation of the flow (a
    Gauss-Markov process: flow = ``flow_m3ps`` x level x (1 + variation), at least 0; the flow signal the
    controller gets measures it); ``start_surge``, the extra flow when the auger starts (the grain standing in the
    tube), a fraction of the nominal flow decaying as exp(-t / ``start_surge_tau_s``) from each start."""

    pivot_xyz_m: tuple[float, float, float] = (-2.0, 1.5, 3.8)
    """Auger pivot in the combine body frame, m."""
    length_m: PosFloat = 6.0
    """Length from the pivot to the spout, m."""
    swing_deg: float = 90.0
    """Swing from the combine's forward axis towards its left, deg (90: straight out to the left)."""
    elevation_deg: float = 8.0
    """Elevation of the tube above the horizontal, deg."""
    tube_radius_m: PosFloat = 0.2
    """Radius of the auger tube (drawn and checked for collisions), m."""
    flow_m3ps: NonNegFloat = 0.125
    """Grain flow while running at full speed, m^3/s."""
    spool_up_s: NonNegFloat = 1.0
    """Time from off to full flow, s."""
    run_out_s: NonNegFloat = 1.0
    """Time from full flow to none after the auger is switched off, s."""
    exit_speed_mps: NonNegFloat = 3.0
    """Speed of the grain leaving the spout relative to the combine, m/s."""
    exit_down_deg: float = 60.0
    """Angle below the horizontal at which the grain leaves the spout, deg."""
    stream_radius_m: PosFloat = 0.15
    """Radius of the grain stream at full flow, m."""
    flow_variation: GaussMarkov = GaussMarkov()
    """Yield-driven relative variation of the flow (a Gauss-Markov process; sigma 0: none)."""
    start_surge: float = Field(default=0.0, ge=0.0, le=2.0, allow_inf_nan=False)
    """Extra flow at each start of the auger, a fraction of the nominal flow, decaying with start_surge_tau_s."""
    start_surge_tau_s: PosFloat = 1.0
    """Time constant of the start surge's decay, s."""


class Tractor(Model):
    """Tractor towing the cart: kinematic bicycle with drivetrain and steering lags and limits.

    The tractor body origin is the centre of its drawn box; the bicycle model runs about the rear axle at body
    x = ``rear_axle_x_m``; the hitch is ``hitch_offset_m`` behind the rear axle. The drivetrain is a first-order
    lag (``drivetrain_tau_s``) with acceleration / braking limits; the steering a first-order lag
    (``steer_tau_s``) with angle and rate limits. The tractor does not reverse (speed command >= 0). ``slip``:
    its wheels' longitudinal slip (docs/field.md).
    """

    wheelbase_m: PosFloat = 3.0
    """Wheelbase of the bicycle model, m."""
    hitch_offset_m: PosFloat = 1.5
    """Distance of the hitch behind the rear axle, m."""
    drivetrain_tau_s: PosFloat = 0.5
    """Time constant of the drivetrain's first-order lag, s."""
    accel_max_mps2: PosFloat = 1.0
    """Largest acceleration, m/s^2."""
    brake_max_mps2: PosFloat = 3.0
    """Largest deceleration, m/s^2."""
    steer_tau_s: PosFloat = 0.2
    """Time constant of the steering's first-order lag, s."""
    steer_max_deg: PosFloat = 35.0
    """Largest steering angle, deg."""
    steer_rate_max_degps: PosFloat = 30.0
    """Largest steering rate, deg/s."""
    max_speed_mps: PosFloat = 12.0
    """Largest speed, m/s (the tractor does not reverse)."""
    rear_axle_x_m: float = -2.0
    """Position of the rear axle along the body x axis (the body origin is the centre of the drawn box), m."""
    length_m: PosFloat = 6.0
    """Length of the drawn body box, m."""
    width_m: PosFloat = 2.6
    """Width of the drawn body box, m."""
    height_m: PosFloat = 3.3
    """Height of the drawn body box, m."""
    mesh_file: Path | None = None
    """A mesh (any format trimesh reads) drawn instead of the boxes, relative to the scenario file."""
    slip: Slip = Slip()
    """Longitudinal wheel slip: ground speed = wheel speed x (1 - slip)."""


class Cart(Model):
    """Grain cart: open-top box on a single axle, towed by a tongue from the tractor hitch.

    Cart body frame: origin on the ground under the centre of the interior footprint, x forward (towing
    direction), y left, z up. Interior box: |x| <= L/2, |y| <= W/2, floor_height <= z <= floor_height + D.
    The cart grid frame (height map, sections) is derived in ``cosim.world.geometry``.
    """

    interior_length_m: PosFloat = 6.0
    """Interior length (towing direction), m."""
    interior_width_m: PosFloat = 3.0
    """Interior width, m."""
    interior_depth_m: PosFloat = 2.0
    """Interior depth from the floor to the wall top, m."""
    floor_height_m: PosFloat = 1.0
    """Height of the cart floor above the ground, m."""
    wall_thickness_m: PosFloat = 0.08
    """Thickness of the walls, m."""
    rim_width_m: PosFloat = 0.12
    """Width of the rim on top of the walls, m."""
    rim_height_m: PosFloat = 0.06
    """Height of the rim above the wall top, m."""
    tongue_length_m: PosFloat = 5.0
    """Length of the tongue from the hitch to the cart, m."""
    mesh_file: Path | None = None
    """A mesh (any format trimesh reads) drawn instead of the boxes, relative to the scenario file."""

    @property
    def rim_top_m(self) -> float:
        """Height of the rim top above the ground, m."""
        return self.floor_height_m + self.interior_depth_m + self.rim_height_m

    @property
    def volume_m3(self) -> float:
        """Interior volume to the wall top, m^3."""
        return self.interior_length_m * self.interior_width_m * self.interior_depth_m

    def grid_shape(self, cell_m: float) -> tuple[int, int]:
        """(nx, ny) cells of a grid of ``cell_m`` over the interior (nx = round(length / cell), at least 1): the
        controller's and the perceived height map's grid."""
        return max(1, round(self.interior_length_m / cell_m)), max(1, round(self.interior_width_m / cell_m))


class MachineSync(Model):
    """Machine Sync: the combine holds the cart at an offset; the offloading controller nudges the setpoint.

    Offsets are of the spout-over-cart geometry: ``lateral_offset_m`` is the lateral distance between the
    combine and cart body origins (cart to the combine's left); ``longitudinal_offset_m`` is the cart body
    origin's distance ahead (+) or behind (-) the combine body origin at the start. The default puts the spout
    of the default auger over the middle of the cart's first section (grid x = 0.35 m).

    Feedback law (``dynamics_proc.vehicles.machine_sync``): the tractor's wanted velocity is the velocity of its setpoint
    plus ``kp_long`` / ``kp_lat`` (1/s) times the position error in combine axes; the heading follows that
    velocity's direction with gain ``heading_gain_ps`` (1/s). ``initial_*_error_m`` displace the tractor from
    its setpoint at t = 0 (combine axes, m).

    In a field (docs/field.md): ``gnss`` is each receiver's horizontal position error per axis (combine and
    tractor, independent; RTK class about 0.02 m with a correlation time of tens of seconds): Machine Sync steers
    on the measured positions and the controller aims with the relative pose they give; ``radio_latency_s`` delays
    the combine's pose on its way to the tractor (``latency_compensation``: extrapolated over the delay with the
    speed and yaw rate it came with); ``actuation_delay_s`` is a dead time between the tractor's commands and its
    drivetrain and steering (on top of their lags).
    """

    longitudinal_offset_m: float = -4.65
    """Cart body origin ahead (+) or behind (-) the combine body origin at the start, m."""
    lateral_offset_m: float = 7.4
    """Lateral distance from the combine to the cart body origin (cart to the combine's left), m."""
    kp_long: PosFloat = 0.8
    """Gain of the longitudinal position error, 1/s."""
    kp_lat: PosFloat = 0.6
    """Gain of the lateral position error, 1/s."""
    heading_gain_ps: PosFloat = 2.0
    """Gain with which the tractor's heading follows its wanted velocity, 1/s."""
    nudge_m: PosFloat = 0.3
    """Step by which a nudge moves the setpoint, m."""
    nudge_min_interval_s: NonNegFloat = 1.0
    """Shortest time between two nudges, s."""
    initial_long_error_m: float = 0.0
    """Tractor displaced from its setpoint along the combine's axis at t = 0, m."""
    initial_lat_error_m: float = 0.0
    """Tractor displaced from its setpoint across the combine's axis at t = 0, m."""
    gnss: GaussMarkov = GaussMarkov(correlation_time_s=30.0)
    """Each GNSS receiver's horizontal position error per axis (RTK class: sigma about 0.02 m)."""
    radio_latency_s: float = Field(default=0.0, ge=0.0, le=2.0, allow_inf_nan=False)
    """Delay of the combine's pose on its way to the tractor, s."""
    latency_compensation: bool = True
    """Extrapolate the delayed pose over the latency with the speed and yaw rate it came with."""
    actuation_delay_s: float = Field(default=0.0, ge=0.0, le=2.0, allow_inf_nan=False)
    """Dead time between the tractor's commands and its drivetrain and steering, s."""
