"""The top-level scenario record: timing, mode, and every section. Owned by cosim."""
from __future__ import annotations

import math
from typing import Literal

from pydantic import Field, ValidationInfo, field_validator

from .base import Model, PosFloat
from .cameras import DEPTH_KINDS, Camera, LidarSensor, SensorMap, Sensors, StereoCamera
from .control import Controller, Grain, Integrator
from .fmu import Vehicles
from .machines import Auger, Cart, Combine, Crop, MachineSync, Tractor
from .outcome import Outcome
from .rendering import Render
from .sensing import Perception, Sensor

__all__ = ["Timing", "Outputs", "Scenario", "FORMAT_VERSION", "RATIO_TOLERANCE"]

FORMAT_VERSION = 1
#: relative tolerance when checking that a rate ratio is an integer
RATIO_TOLERANCE = 1e-9


def _integer_ratio(num: float, den: float) -> int | None:
    """num / den as an int when it is one to RATIO_TOLERANCE, else None."""
    r = num / den
    n = round(r)
    return n if n >= 1 and abs(r - n) <= RATIO_TOLERANCE * max(1.0, r) else None


class Timing(Model):
    """Co-simulation clock: one sensor frame per ring turn, an integer number of dynamics steps in it."""

    sensor_period_s: PosFloat = 0.1
    dynamics_dt_s: PosFloat = 0.01
    latency_frames: int = Field(default=1, ge=0, le=100)
    #: with latency_frames >= 1 (or ground-truth feedback) perception of frame m runs while dynamics and the
    #: renderer do frame m + 1 and publishes its outputs at its next turn; the results are the same either way
    #: (cosim.runtime.participant.perception_overlaps)
    overlap_perception: bool = True
    handoff_timeout_s: PosFloat = 30.0
    startup_timeout_s: PosFloat = 120.0

    @field_validator("dynamics_dt_s")
    @classmethod
    def _ratio(cls, dt: float, info: ValidationInfo) -> float:
        # a field validator (after sensor_period_s) so the loader reports it at the dynamics_dt_s line
        period = info.data.get("sensor_period_s")
        if period is not None and _integer_ratio(period, dt) is None:
            raise ValueError(
                f"sensor_period_s / dynamics_dt_s = {period / dt:g} is not an integer >= 1; choose a dynamics "
                "step that divides the sensor period"
            )
        return dt

    @property
    def steps_per_frame(self) -> int:
        """Dynamics steps per sensor frame (validated integer)."""
        n = _integer_ratio(self.sensor_period_s, self.dynamics_dt_s)
        assert n is not None
        return n


class Outputs(Model):
    """What a run writes beside summary.json and timeseries.csv."""

    figures: bool = True
    report: bool = False


class Scenario(Model):
    """A whole scenario, as loaded from YAML and validated before anything starts."""

    format_version: Literal[1]
    name: str = Field(default="scenario", pattern=r"^[A-Za-z0-9_.-]{1,64}$")
    description: str = ""
    seed: int = Field(default=0, ge=0, le=2**63 - 1)
    duration_s: PosFloat = 60.0
    feedback: Literal["ground_truth", "perception"] = "perception"
    renderer: Literal["gl", "mock", "none"] = "gl"
    viewer: bool = False
    timing: Timing = Timing()
    crop: Crop = Crop()
    combine: Combine = Combine()
    auger: Auger = Auger()
    tractor: Tractor = Tractor()
    cart: Cart = Cart()
    machine_sync: MachineSync = MachineSync()
    vehicles: Vehicles = Vehicles()
    grain: Grain = Grain()
    controller: Controller = Controller()
    integrator: Integrator = Integrator()
    sensor: Sensor = Sensor()
    #: named sensors (docs/cameras.md): name -> a sensor whose ``kind`` is lidar, depth_camera, stereo_camera or
    #: rgb_camera; empty: the one LiDAR of ``sensor:`` (the shorthand), named ``lidar``
    sensors: Sensors = {}
    render: Render = Render()
    perception: Perception = Perception()
    outputs: Outputs = Outputs()
    outcome: Outcome = Outcome()
    #: folder searched first for plug-in modules named by import path (the loader sets it to the scenario
    #: file's folder; '' only sys.path); carried to the run's processes so that they import the same code
    plugin_dir: str = ""

    @field_validator("renderer")
    @classmethod
    def _renderer_for_feedback(cls, renderer: str, info: ValidationInfo) -> str:
        # a field validator (not a model validator) so that the problem is reported at the renderer's line, and
        # also when other sections of the scenario are invalid
        if renderer == "none" and info.data.get("feedback") == "perception":
            raise ValueError("feedback 'perception' needs a renderer ('gl' or 'mock'), not 'none'")
        return renderer

    # cross-section checks are field validators on the later section (cart comes before grain and controller),
    # so that each is reported at that section's line and even when unrelated sections are invalid
    @field_validator("grain")
    @classmethod
    def _grain_fits_cart(cls, grain: Grain, info: ValidationInfo) -> Grain:
        cart = info.data.get("cart")
        if cart is not None and grain.initial_fill_m > cart.interior_depth_m:
            raise ValueError(f"initial_fill_m ({grain.initial_fill_m:g}) is above the wall top "
                             f"(cart.interior_depth_m = {cart.interior_depth_m:g}): the cart would already overflow")
        return grain

    @field_validator("controller")
    @classmethod
    def _controller_fits_cart(cls, controller: Controller, info: ValidationInfo) -> Controller:
        cart = info.data.get("cart")
        if cart is None:
            return controller
        if controller.target_fill_m > cart.interior_depth_m:
            raise ValueError(f"target_fill_m ({controller.target_fill_m:g}) is above the wall top "
                             f"(cart.interior_depth_m = {cart.interior_depth_m:g}): grain that high spills")
        cells = cart.grid_shape(controller.grid_cell_m)[0]                 # as the controller grids the cart
        if cells < controller.sections:
            raise ValueError(f"{controller.sections} sections need at least one grid cell each, but "
                             f"cart.interior_length_m / grid_cell_m gives {cells}; use fewer sections or a finer "
                             "grid_cell_m")
        return controller

    @field_validator("sensors")
    @classmethod
    def _sensor_set(cls, sensors: SensorMap, info: ValidationInfo) -> SensorMap:
        if not sensors:
            return sensors
        lidars = [n for n, s in sensors.items() if s.kind == "lidar"]
        if len(lidars) > 1:
            raise ValueError(f"{len(lidars)} LiDARs ({', '.join(lidars)}): a scenario has at most one (its blocks "
                             "beams_depth and lidar_points are single); add cameras beside it instead")
        if info.data.get("sensor", Sensor()) != Sensor():
            raise ValueError("both sensor: and sensors: are given; sensor: is the shorthand for one LiDAR, so put "
                             "that LiDAR under sensors: with kind: lidar and remove sensor:")
        if info.data.get("renderer") == "mock":
            stereo = [n for n, s in sensors.items() if isinstance(s, StereoCamera)]
            if stereo:
                raise ValueError(f"stereo camera {stereo[0]!r} needs the GL renderer: the stereo matcher works on "
                                 "textured left and right images, and the mock renderer's plain shading has no "
                                 "texture to match; use renderer: gl (a depth_camera works with the mock)")
        return sensors

    @property
    def sensor_set(self) -> dict[str, LidarSensor | Camera]:
        """Every sensor by name, in declaration order: ``sensors``, or with none given the LiDAR of ``sensor:``
        under the name ``lidar`` (a :class:`LidarSensor` copy of it)."""
        if self.sensors:
            return dict(self.sensors)
        return {"lidar": LidarSensor(kind="lidar", **dict(self.sensor))}

    @property
    def lidar(self) -> Sensor | None:
        """The LiDAR: ``sensor:`` itself when ``sensors`` is empty, else the one of kind lidar (None: no LiDAR)."""
        if not self.sensors:
            return self.sensor
        return next((s for s in self.sensors.values() if s.kind == "lidar"), None)

    @property
    def lidar_name(self) -> str | None:
        """The LiDAR's name (``lidar`` for the shorthand), None when there is none."""
        if not self.sensors:
            return "lidar"
        return next((n for n, s in self.sensors.items() if s.kind == "lidar"), None)

    @property
    def cameras(self) -> dict[str, Camera]:
        """The camera sensors by name, in declaration order."""
        return {n: s for n, s in self.sensors.items() if isinstance(s, Camera)}

    @property
    def depth_sensors(self) -> tuple[str, ...]:
        """Names of the sensors that give depth (the LiDAR, depth and stereo cameras), in declaration order."""
        return tuple(n for n, s in self.sensor_set.items() if s.kind in DEPTH_KINDS)

    @property
    def frames(self) -> int:
        """Sensor frames in the run (ring turns after the initial frame 0)."""
        return max(1, math.ceil(self.duration_s / self.timing.sensor_period_s - RATIO_TOLERANCE))

    @property
    def needs_renderer(self) -> bool:
        """Whether the renderer takes part: perception feedback or a viewer needs images."""
        return self.renderer != "none" and (self.feedback == "perception" or self.viewer)

    @property
    def needs_perception(self) -> bool:
        """Whether perception takes part: perception feedback, or a viewer that shows its outputs."""
        return self.needs_renderer

    @property
    def participants(self) -> tuple[str, ...]:
        """Ring order of the participants this scenario needs (dynamics always first)."""
        ring = ["dynamics"]
        if self.needs_renderer:
            ring.append("renderer")
        if self.needs_perception:
            ring.append("perception")
        return tuple(ring)
