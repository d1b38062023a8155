"""The dynamics role driven from outside: the vehicles and the controller live in another tool (a Simulink model
driving graincosim exported as an FMU, docs/fmu.md); this participant keeps the grain fill model and publishes
the same blocks as :mod:`dynamics_proc.participant`, so that the renderer and perception run unchanged.

Each frame m (t_{m-1} .. t_m) takes the :class:`WorldInputs` set before it, held over the frame (zero-order
hold): the three bodies' planar poses, the spout position, whether the auger runs and the grain flow. The
grain that leaves the spout over the frame (``flow_m3ps * sensor_period_s``) lands where the stream from the
spout first meets a surface, computed on the frame's heights as the built-in model does
(:func:`dynamics_proc.grain.auger.first_surface`, :func:`dynamics_proc.grain.fill.deposit`); grain landing outside the
interior or sliding over a wall top is spill. Frame 0 publishes the inputs' scene with nothing delivered.

``dyn_state`` fields that belong to the outside models (vehicle speeds and steering, Machine Sync setpoint and
errors, the controller's Fig 9 signals and section estimates) are NaN (0 for the integer ones). The ground is
flat: every body stands level on it (z, roll and pitch 0); a scenario with terrain is refused
(:func:`create`), since planar poses do not say how the bodies stand on it.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

import dynamics_proc.grain.auger as ag
from cosim.errors import FrameMismatch
from cosim.fmi.export.contract import TERRAIN_REFUSED
from cosim.scenario.config import Scenario
from cosim.world.geometry import cart_grid_from_body, invert, vehicle_pose
from cosim.world.terrain import terrain_of
from dynamics_proc.blocks import SECTION_FIELD, STATE_FIELDS, WRITER, state_fields
from dynamics_proc.grain.fill import GrainGrid, deposit, initial_heights, volume
from dynamics_proc.vehicles.motion import CX, CY, CYAW, VehicleParams, cart_pose, initial_state, tractor_pose

if TYPE_CHECKING:
    from shm_schema import Segment

__all__ = ["BODIES", "TERRAIN_REFUSED", "WorldInputs", "GrainWorld", "GrainParams", "grain_params", "initial_inputs",
           "initial_grain", "step_grain", "external_signals", "ExternalDynamicsParticipant", "create"]


#: the bodies whose planar poses the inputs give
BODIES = ("combine", "tractor", "cart")


@dataclass(frozen=True)
class WorldInputs:
    """What the outside vehicle-and-controller model gives each frame (world frame, SI): the body origins and
    headings of the combine, the tractor and the cart (``dyn_state``'s ``<entity>_{x_m,y_m,yaw_rad}``; the cart's
    origin is its interior centre on the ground), the auger spout (world, m), whether the auger runs, and the
    grain flow leaving the spout (m^3/s, >= 0)."""

    combine_x_m: float
    combine_y_m: float
    combine_yaw_rad: float
    tractor_x_m: float
    tractor_y_m: float
    tractor_yaw_rad: float
    cart_x_m: float
    cart_y_m: float
    cart_yaw_rad: float
    spout_x_m: float
    spout_y_m: float
    spout_z_m: float
    auger_on: bool = False
    flow_m3ps: float = 0.0


@dataclass(frozen=True)
class GrainWorld:
    """The grain after frame ``frame`` (time ``t_s``): heights (nx, ny) float64 m on the grain grid (cart grid
    frame), cumulative volumes m^3, the stream's impact and rows (as :class:`dynamics_proc.model.World`)."""

    frame: int
    t_s: float
    heights: np.ndarray
    initial_m3: float
    delivered_m3: float
    spilled_m3: float
    spilled_outside_m3: float
    impact: ag.Impact
    stream: np.ndarray               # (64, 4) float32 world rows [x, y, z, radius]
    stream_points: int
    inputs: WorldInputs


@dataclass(frozen=True)
class GrainParams:
    """What the grain model needs of the scenario (SI), derived once: auger geometry and flow, grain grid and its
    cap, the cart's grid-from-body transform, the frame period, the section count, the target fill and the
    combine speed (reported)."""

    auger: ag.AugerParams
    grid: GrainGrid
    cap: np.ndarray
    grid_from_cart_body: np.ndarray
    frame_dt_s: float
    sections: int
    target_m: float
    combine_speed_mps: float


def grain_params(s: Scenario) -> GrainParams:
    """The grain model's parameters of scenario ``s``."""
    g = GrainGrid.from_scenario(s)
    return GrainParams(ag.AugerParams.from_scenario(s), g, g.cap(), cart_grid_from_body(s.cart),
                   s.timing.sensor_period_s, s.controller.sections, s.controller.target_fill_m, s.combine.speed_mps)


def initial_inputs(s: Scenario) -> WorldInputs:
    """The inputs at the scenario's initial state (the built-in model's t = 0: the tractor at its Machine Sync
    setpoint plus the initial errors), auger off: the FMU's start values."""
    vp = VehicleParams.from_scenario(s)
    x = initial_state(s, vp)
    sp = ag.spout_world(float(x[CX]), float(x[CY]), float(x[CYAW]), ag.AugerParams.from_scenario(s))
    return WorldInputs(float(x[CX]), float(x[CY]), float(x[CYAW]), *tractor_pose(x, vp), *cart_pose(x, vp),
                       *(float(v) for v in sp))


def _grid_from_world(u: WorldInputs, p: GrainParams) -> np.ndarray:
    """Cart grid frame from world (4, 4) at the cart pose ``u`` gives."""
    return p.grid_from_cart_body @ invert(vehicle_pose(u.cart_x_m, u.cart_y_m, u.cart_yaw_rad))


def _spout(u: WorldInputs) -> np.ndarray:
    return np.array([u.spout_x_m, u.spout_y_m, u.spout_z_m])


def _stream(u: WorldInputs, h: np.ndarray, p: GrainParams) -> tuple[ag.Impact, np.ndarray, int]:
    """Where the stream from the spout ``u`` gives first meets a surface of ``h``, and its rows."""
    sp = _spout(u)
    vel = ag.exit_velocity_world(u.combine_yaw_rad, p.auger)
    imp = ag.first_surface(sp, vel, _grid_from_world(u, p), h, p.grid.cell_m, p.auger)
    level = max(u.flow_m3ps, 0.0) / p.auger.flow_m3ps
    rows = ag.stream_rows(sp, vel, imp.time_s, p.auger.stream_radius_m * math.sqrt(level))
    return imp, rows, (ag.STREAM_ROWS if u.flow_m3ps > 0.0 else 0)


def initial_grain(s: Scenario, u: WorldInputs) -> GrainWorld:
    """Frame 0: the scenario's initial fill, nothing delivered, the stream of ``u``."""
    p = grain_params(s)
    h = initial_heights(p.grid, s.grain.initial_fill_m)
    imp, rows, n = _stream(u, h, p)
    return GrainWorld(0, 0.0, h, volume(h, p.grid), 0.0, 0.0, 0.0, imp, rows, n, u)


def step_grain(w: GrainWorld, u: WorldInputs, p: GrainParams) -> GrainWorld:
    """The grain after the next frame, ``u`` held over it."""
    vol = max(u.flow_m3ps, 0.0) * p.frame_dt_s
    imp, rows, n = _stream(u, w.heights, p)
    h, spill, outside = w.heights, 0.0, 0.0
    if vol > 0.0:
        if imp.surface == ag.SURFACE_GRAIN:
            h, spill = deposit(h, float(imp.grid[0]), float(imp.grid[1]), vol, p.grid, p.cap)
        else:
            outside = vol
    return GrainWorld(w.frame + 1, (w.frame + 1) * p.frame_dt_s, h, w.initial_m3, w.delivered_m3 + vol,
                      w.spilled_m3 + spill + outside, w.spilled_outside_m3 + outside, imp, rows, n, u)


def external_signals(w: GrainWorld, p: GrainParams) -> dict[str, float]:
    """The ``dyn_state`` fields of ``w``: the inputs' poses, the stream and the volumes; the outside models'
    fields NaN (0 for integers)."""
    u = w.inputs
    d: dict[str, float] = {n: (0 if dt == "i8" else math.nan) for n, _, dt, _ in STATE_FIELDS}
    d.update({k: float(v) for k, v in asdict(u).items() if k in d})
    g = _grid_from_world(u, p)
    spg = g[:3, :3] @ _spout(u) + g[:3, 3]
    in_cart = volume(w.heights, p.grid) - w.initial_m3
    level = max(u.flow_m3ps, 0.0) / p.auger.flow_m3ps
    d.update({
        "t_s": w.t_s, "frame": w.frame, "combine_speed_mps": p.combine_speed_mps,
        "auger_on": int(u.auger_on), "flow_level": level, "flow_m3ps": max(u.flow_m3ps, 0.0),
        "impact_x_m": float(w.impact.world[0]), "impact_y_m": float(w.impact.world[1]),
        "impact_z_m": float(w.impact.world[2]), "impact_valid": int(w.stream_points > 0),
        "impact_surface": w.impact.surface, "impact_gx_m": float(w.impact.grid[0]),
        "impact_gy_m": float(w.impact.grid[1]), "impact_gz_m": float(w.impact.grid[2]),
        "stream_points": w.stream_points, "actual_auger_x_m": float(spg[0]), "actual_auger_y_m": float(spg[1]),
        "target_fill_m": p.target_m, "delivered_m3": w.delivered_m3, "in_cart_m3": in_cart,
        "spilled_m3": w.spilled_m3, "spilled_outside_m3": w.spilled_outside_m3,
        "cart_grain_m3": w.initial_m3 + in_cart, "peak_height_m": float(w.heights.max()),
    })
    d.update({SECTION_FIELD.format(k=k): math.nan for k in range(1, p.sections + 1)})
    for body in BODIES:                               # flat ground: every body level, on the ground
        d.update({f"{body}_{q}": 0.0 for q in ("z_m", "roll_rad", "pitch_rad") if f"{body}_{q}" in d})
    return d


class ExternalDynamicsParticipant:
    """The ring's dynamics member when the vehicles and the controller are outside: :meth:`set_inputs` before
    each step (the inputs are held until set again); ``step(frame)`` publishes ``dyn_state``, ``stream`` and
    ``heightmap_truth`` as :class:`dynamics_proc.participant.DynamicsParticipant` does."""

    name = WRITER

    def __init__(self, scenario: Scenario):
        self.scenario = scenario
        self.params = grain_params(scenario)
        self.inputs = initial_inputs(scenario)
        self.world: GrainWorld | None = None
        self._names = tuple(f.name for f in state_fields(scenario.controller.sections))
        self._seg: Segment | None = None
        self._next = 0

    def set_inputs(self, **values: float) -> None:
        """Set some of the :class:`WorldInputs` fields for the next frame (the others keep their values)."""
        self.inputs = replace(self.inputs, **values)

    def start(self, segment: "Segment") -> None:
        """Bind the blocks this participant writes."""
        self._seg = segment

    def step(self, frame: int) -> None:
        """Frame 0: publish the initial scene. Frame m >= 1: deposit the grain of t_{m-1} .. t_m, publish."""
        if self._seg is None:
            raise RuntimeError("dynamics: step() before start()")
        if frame != self._next:
            raise FrameMismatch(f"dynamics expected frame {self._next}, got {frame}", process=self.name,
                                frame=frame)
        if frame == 0:
            self.world = initial_grain(self.scenario, self.inputs)
        else:
            self.world = step_grain(self.world, self.inputs, self.params)
        w, seg = self.world, self._seg
        sig = external_signals(w, self.params)
        with seg.write("dyn_state", frame) as v:
            v.assign([sig[f] for f in self._names])
        with seg.write("stream", frame) as s:
            s[...] = w.stream
        with seg.write("heightmap_truth", frame) as h:
            h[...] = w.heights
        self._next = frame + 1

    def close(self) -> None:
        """Drop the segment (it belongs to the runtime)."""
        self._seg = None


def create(scenario: Scenario) -> ExternalDynamicsParticipant:
    """The externally driven dynamics participant for ``scenario``; ValueError for a scenario with terrain."""
    if terrain_of(scenario) is not None:
        raise ValueError(TERRAIN_REFUSED)
    return ExternalDynamicsParticipant(scenario)
