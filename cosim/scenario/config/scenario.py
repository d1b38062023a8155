"""The top-level scenario record: timing, mode, and every section. Owned by cosim."""
from __future__ import annotations

import math
from typing import Literal

from pydantic import Field, ValidationInfo, field_validator, model_validator

from .atmosphere import Atmosphere
from .base import Model, PosFloat
from .cameras import DEPTH_KINDS, Camera, LidarSensor, SensorMap, Sensors, StereoCamera
from .control import Controller, Grain, Integrator
from .draws import FieldDraws
from .fmu import Vehicles
from .limits import key_error
from .machines import Auger, Cart, Combine, Crop, MachineSync, Tractor
from .outcome import Outcome
from .rendering import Render
from .sensing import Perception, Sensor
from .terrain import Terrain

__all__ = ["Timing", "Outputs", "Scenario", "FORMAT_VERSION", "RATIO_TOLERANCE", "MAX_SENSOR_PERIOD_S",
           "MAX_GRID_CELLS"]

FORMAT_VERSION = 1
#: relative tolerance when checking that a rate ratio is an integer
RATIO_TOLERANCE = 1e-9
#: longest sensor period, s: a LiDAR frame rate below 1 Hz is none this platform models (100 is milliseconds typed
#: as seconds: 3 frames for a 200 s run)
MAX_SENSOR_PERIOD_S = 1.0
#: most cells of a height-map grid over the cart (grain.cell_m, controller.grid_cell_m): 2048 x 2048, a 1.5 mm
#: cell on the default cart; each cell costs the fill model and perception several float64 arrays per frame
MAX_GRID_CELLS = 1 << 22


def _grid_problem(cart: Cart, cell_m: float) -> str | None:
    """Why a grid of ``cell_m`` over ``cart``'s interior is too large to hold, None when it is not."""
    nx, ny = cart.interior_length_m / cell_m, cart.interior_width_m / cell_m
    if nx * ny <= MAX_GRID_CELLS:
        return None
    smallest = math.sqrt(cart.interior_length_m * cart.interior_width_m / MAX_GRID_CELLS)
    return (f"{cell_m:g} m cells grid the {cart.interior_length_m:g} x {cart.interior_width_m:g} m cart interior "
            f"into {nx:,.0f} x {ny:,.0f} cells; at most {MAX_GRID_CELLS:,} cells fit (a cell of at least "
            f"{smallest:.2g} m on this cart)")


def _integer_ratio(num: float, den: float) -> int | None:
    """num / den as an int when it is one to RATIO_TOLERANCE, else None."""
    r = num / den
    n = round(r)
    return n if n >= 1 and abs(r - n) <= RATIO_TOLERANCE * max(1.0, r) else None


class Timing(Model):
    """Co-simulation clock: one sensor frame per ring turn, an integer number of dynamics steps in it."""

    sensor_period_s: float = Field(default=0.1, gt=0.0, le=MAX_SENSOR_PERIOD_S)
    """One LiDAR frame = one turn of the process ring, s (at most 1 s: a sensor frame rate of at least 1 Hz)."""
    dynamics_dt_s: PosFloat = 0.01
    """Dynamics integration step, s; must divide sensor_period_s (an integer number of steps per frame)."""
    latency_frames: int = Field(default=1, ge=0, le=100)
    """Frames between a perception output and the controller seeing it (0-100)."""
    schedule: Literal["sequential", "overlapped", "pipelined"] = "pipelined"
    """How the processes take turns (docs/architecture.md); every schedule gives the same results, to the bit.
    sequential: one token ring (dynamics, renderer, perception, supervisor), each member's frame after the one
    before it. overlapped: the token ring, with perception of frame m running while dynamics and the renderer do
    frame m + 1 (it publishes at its next turn; with latency_frames >= 1 or ground-truth feedback,
    cosim.runtime.participant.perception_overlaps). pipelined: each process waits only for the frames it reads,
    so that dynamics, the renderer and perception work on neighbouring frames at once (perception overlapping as
    in overlapped); a run with one process (no renderer or perception) or on one core runs as the token ring."""
    handoff_timeout_s: PosFloat = 30.0
    """CPU time one process may spend on one frame before the run stops with HandoffTimeout naming it (a loop
    that never ends), s of the process's own CPU time, not of the clock: a process slowed by a busy machine is
    waited for, and one that makes no progress at all is named hung within about a second
    (docs/reliability.md)."""
    startup_timeout_s: PosFloat = 120.0
    """CPU time one process may spend starting (imports, models, GL context, shaders) before the run stops with
    HandoffTimeout naming it, s of its own CPU time; a start-up that makes no progress is named hung."""

    @model_validator(mode="before")
    @classmethod
    def _one_schedule_key(cls, data):
        """``overlap_perception`` is part of ``schedule``: a scenario that names it is told which value to use."""
        if isinstance(data, dict) and "overlap_perception" in data:
            raise key_error("Timing", ("overlap_perception",), "not a key: whether perception overlaps the next frame "
                            "is part of timing.schedule: sequential (no overlap), overlapped or pipelined (the "
                            "default; both overlap)", data["overlap_perception"])
        return data

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
    """Draw the run's figures (PNG) into the run directory at the end."""
    report: bool = False
    """Also write report.html with the figures."""


class Scenario(Model):
    """A whole scenario, as loaded from YAML and validated before anything starts."""

    format_version: Literal[1]
    """Version of the scenario format; this version of graincosim reads 1. The only required key."""
    name: str = Field(default="scenario", pattern=r"^[A-Za-z0-9_.-]{1,64}$")
    """Name of the scenario: letters, digits, '_', '.', '-' (1-64); names the default run directory."""
    description: str = ""
    """Free text describing the scenario (`launch.py list` shows its first sentence)."""
    seed: int = Field(default=0, ge=0, le=2**63 - 1)
    """Random seed of everything random in the run (noise, dropout, accuracy beams); same seed, same results."""
    duration_s: PosFloat = 60.0
    """Simulated time, s."""
    feedback: Literal["ground_truth", "perception"] = "perception"
    """What the controller sees: perception (the perceived height map) or ground_truth (the true one)."""
    renderer: Literal["gl", "mock", "none"] = "gl"
    """gl (OpenGL), mock (CPU ray caster, no OpenGL needed) or none (ground-truth feedback only)."""
    viewer: bool = False
    """Serve the live dashboard while the run goes (the CLI's --viewer sets it)."""
    timing: Timing = Timing()
    """Co-simulation clock: sensor period, dynamics step, latency, timeouts."""
    crop: Crop = Crop()
    """The grain being offloaded: crop, density, angle of repose."""
    combine: Combine = Combine()
    """The combine harvester: path, speed, size."""
    auger: Auger = Auger()
    """The combine's unloading auger: geometry and flow."""
    tractor: Tractor = Tractor()
    """The tractor towing the cart: vehicle model, lags and limits, size."""
    cart: Cart = Cart()
    """The grain cart: interior, walls, rim, tongue."""
    machine_sync: MachineSync = MachineSync()
    """Machine Sync: how the combine holds the cart beside it, and the nudges."""
    terrain: Terrain = Terrain()
    """The ground the machines drive on: flat, or uneven with its tilt and bumps."""
    vehicles: Vehicles = Vehicles()
    """Replaceable vehicle dynamics (an FMU for the tractor and cart)."""
    grain: Grain = Grain()
    """The grain fill model: height-map cell, initial fill, heap radius."""
    controller: Controller = Controller()
    """The offloading controller: target, strategy, sections, safety margins, estimator."""
    integrator: Integrator = Integrator()
    """Integration of the continuous vehicle states within a frame."""
    sensor: Sensor = Sensor()
    """The LiDAR of the one-LiDAR shorthand (used when sensors is empty): mount, beam pattern, range limits,
    noise, depth codec."""
    sensors: Sensors = {}
    """Named sensors (docs/cameras.md): name -> a sensor whose kind is lidar, depth_camera, stereo_camera or
    rgb_camera, each with its mount; empty: the one LiDAR of sensor, named lidar."""
    render: Render = Render()
    """Renderer options: camera rig, image sizes, mock scale."""
    perception: Perception = Perception()
    """Offloading perception: resampling, height map, impact, accuracy evaluation, plug-ins."""
    atmosphere: Atmosphere = Atmosphere()
    """The air between the sensors and what they see: dust, the grain stream as particles (clear by default)."""
    field: FieldDraws = FieldDraws()
    """What the seed draws of the field (flow, GNSS, profile, roughness, dust, offsets) and within which ranges;
    nothing by default (docs/field.md)."""
    outputs: Outputs = Outputs()
    """Optional outputs of a run: figures, report."""
    outcome: Outcome = Outcome()
    """What the run must achieve to count as done (the run's outcome)."""
    plugin_dir: str = ""
    """Folder searched first for plug-in modules named by import path; the loader sets it to the scenario file's
    folder unless given (a relative one is resolved against the file that gives it, or the working directory with
    --set); '' searches sys.path only. Carried to the run's processes, so that they import the same code."""

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
        if cart is None:
            return grain
        too_large = _grid_problem(cart, grain.cell_m)
        if too_large:
            raise key_error("Grain", ("cell_m",), too_large, grain.cell_m)
        for what, extent in (("length", cart.interior_length_m), ("width", cart.interior_width_m)):
            if _integer_ratio(extent, grain.cell_m) is None:
                n = max(1, round(extent / grain.cell_m))
                raise key_error("Grain", ("cell_m",), f"{grain.cell_m:g} m does not divide the cart interior {what} "
                                f"{extent:g} m; choose a cell that divides it (e.g. {extent / n:g} m)", grain.cell_m)
        if grain.initial_fill_m > cart.interior_depth_m:
            raise key_error("Grain", ("initial_fill_m",), f"initial_fill_m ({grain.initial_fill_m:g}) is above the "
                            f"wall top (cart.interior_depth_m = {cart.interior_depth_m:g}): the cart would already "
                            "overflow", grain.initial_fill_m)
        return grain

    @field_validator("controller")
    @classmethod
    def _controller_fits_cart(cls, controller: Controller, info: ValidationInfo) -> Controller:
        cart = info.data.get("cart")
        if cart is None:
            return controller
        too_large = _grid_problem(cart, controller.grid_cell_m)
        if too_large:
            raise key_error("Controller", ("grid_cell_m",), too_large, controller.grid_cell_m)
        if controller.target_fill_m > cart.interior_depth_m:
            raise key_error("Controller", ("target_fill_m",), f"target_fill_m ({controller.target_fill_m:g}) is "
                            f"above the wall top (cart.interior_depth_m = {cart.interior_depth_m:g}): grain that high "
                            "spills", controller.target_fill_m)
        cells = cart.grid_shape(controller.grid_cell_m)[0]                 # as the controller grids the cart
        if cells < controller.sections:
            raise key_error("Controller", ("sections",), f"{controller.sections} sections need at least one grid "
                            f"cell each, but cart.interior_length_m / grid_cell_m gives {cells}; use fewer sections "
                            "or a finer grid_cell_m", controller.sections)
        return controller

    @field_validator("field")
    @classmethod
    def _profile_keeps_its_order(cls, field: FieldDraws, info: ValidationInfo) -> FieldDraws:
        combine = info.data.get("combine")
        if "profile" not in field.draw or combine is None:
            return field
        from .fielddraw import profile_problem
        points = field.base.get("combine.profile", combine.profile) or ()
        problem = profile_problem(points, field.profile)
        if problem:
            raise key_error("FieldDraws", ("profile",), problem, field.profile.model_dump())
        return field

    @model_validator(mode="after")
    def _draw_the_field(self) -> "Scenario":
        from .fielddraw import realise
        realise(self)
        return self

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
