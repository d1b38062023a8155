"""The system model's frame step: controller -> Machine Sync + vehicles -> auger and stream -> grain fill.

``World`` is the whole ground truth after a frame; :func:`step_frame` maps (world, measurement) to the next
world over one sensor period (``steps_per_frame`` held-input steps of ``dynamics_dt_s``), and
:func:`signals` flattens a world into the ``dyn_state`` fields. Pure: no segment, no I/O, deterministic (with
the built-in controller; a ``controller.model`` plug-in may keep memory of its own, see
dynamics_proc.control.protocol).
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

import dynamics_proc.grain.auger as ag
from cosim.errors import PluginFault
from cosim.scenario.config import Scenario
from cosim.world.geometry import invert, vehicle_pose
from dynamics_proc.blocks import SECTION_FIELD
from dynamics_proc.control.feedforward import turn_compensation
from dynamics_proc.control.protocol import (
    CONTROLLER_POINT,
    ControllerCommand,
    ControllerInput,
    Delivery,
    check_command,
)
from dynamics_proc.grain.fill import deposit, initial_heights, resample, volume
from dynamics_proc.grain.tilt import Tilt, deposit_tilted, settle, tilt_of, tilted_cap
from dynamics_proc.record import signals
from dynamics_proc.state import ModelParams, SpoutGeometry, World
from dynamics_proc.vehicles.fieldsync import (
    FieldState,
    advance_noise,
    advance_vehicles,
    combine_motion,
    flow_factor,
    initial_field,
    measured_state,
    speed_change,
)
from dynamics_proc.vehicles.ground import spout_on_terrain
from dynamics_proc.vehicles.integrators import Stepping, integrate, step_exponential_values
from dynamics_proc.vehicles.machine_sync import sync_command
from dynamics_proc.vehicles.motion import CX, CY, CYAW, cart_pose, initial_state

__all__ = ["ModelParams", "World", "SpoutGeometry", "initial_world", "step_frame", "truth_measurement", "signals",
           "spout_grid", "frame0_state", "SECTION_FIELD"]

def _grid_from_world(x: np.ndarray, p: ModelParams) -> np.ndarray:
    return p.grid_from_cart_body @ invert(vehicle_pose(*cart_pose(x, p.vehicles)))


def spout_grid(x: np.ndarray, p: ModelParams) -> SpoutGeometry:
    """(spout world (3,), exit velocity world (3,), spout grid (3,), grid_from_world (4, 4)) for state x (on the
    terrain: dynamics_proc.vehicles.ground.spout_on_terrain)."""
    if p.stance is not None:
        return spout_on_terrain(x, p.vehicles, p.auger, p.grid_from_cart_body, p.stance)
    sp = ag.spout_world(float(x[CX]), float(x[CY]), float(x[CYAW]), p.auger)
    vel = ag.exit_velocity_world(float(x[CYAW]), p.auger)
    g = _grid_from_world(x, p)
    return sp, vel, g[:3, :3] @ sp + g[:3, 3], g


def _stream(spout: SpoutGeometry, h: np.ndarray, level: float, active: bool,
            p: ModelParams) -> tuple[ag.Impact, np.ndarray, int]:
    sp, vel, _, g = spout
    imp = ag.first_surface(sp, vel, g, h, p.grid.cell_m, p.auger, tilted=_tilt(spout) is not None)
    rows = ag.stream_rows(sp, vel, imp.time_s, p.auger.stream_radius_m * math.sqrt(max(level, 0.0)))
    return imp, rows, (ag.STREAM_ROWS if active else 0)


def initial_world(s: Scenario, p: ModelParams | None = None) -> World:
    """Frame 0: vehicles at their setpoint (plus initial errors), flat initial fill, auger off."""
    p = p or ModelParams.from_scenario(s)
    x = initial_state(s, p.vehicles)
    h = initial_heights(p.grid, s.grain.initial_fill_m)
    setpoint = (s.machine_sync.longitudinal_offset_m, s.machine_sync.lateral_offset_m)
    spout = spout_grid(x, p)
    imp, rows, n = _stream(spout, h, 0.0, False, p)
    spg = spout[2]
    out = ControllerCommand(0, False, float(spg[0]), float(spg[0]), -1, np.full(p.control.sections, np.nan), False,
                            False, 0.0)
    try:
        state = p.controller.initial_state()
    except Exception as e:  # noqa: BLE001 - a plug-in's failure is reported with its name
        raise PluginFault(p.controller_ref, CONTROLLER_POINT, f"initial_state raised {type(e).__name__}: {e}",
                          0) from e
    field = initial_field(p.field, x, p.vehicles, p.dt_s) if p.field is not None else None
    return World(0, 0.0, x, 0.0, h, volume(h, p.grid), 0.0, 0.0, 0.0, setpoint, state, out, imp, rows, n, spout,
                 field=field)


def frame0_state(s: Scenario) -> tuple[dict, np.ndarray]:
    """The ``dyn_state`` fields and the truth height map ((nx, ny) float32 m) of frame 0 of ``s``, from the scenario
    alone: the built-in controller and vehicle model stand in for any plug-in or FMU (nothing of the user's is opened
    or stepped; the scenario checks, cosim.scenario.plausibility, look at this world's geometry)."""
    geometry = s.model_copy(update={
        "controller": s.controller.model_copy(update={"model": "section_fill", "model_options": {},
                                                      "strategy": "front_to_back", "strategy_options": {}, "fmu": None}),
        "vehicles": type(s.vehicles)()})
    p = ModelParams.from_scenario(geometry)
    w = initial_world(geometry, p)
    state = signals(w, p)
    state["stream_points"] = 0
    return state, np.asarray(w.heights, dtype=np.float32)


def truth_measurement(h: np.ndarray, p: ModelParams) -> np.ndarray:
    """Ground-truth height map resampled to the controller grid, (nxc, nyc) float64 m."""
    return resample(h, p.grid.cell_m, p.control.grid_cell_m, p.grid.length_m, p.grid.width_m)


def _tilt(spout: SpoutGeometry) -> Tilt | None:
    """The cart's tilt (dynamics_proc.grain.tilt) from the grid_from_world of ``spout``, None when level."""
    g = spout[3]
    return tilt_of(invert(g)) if g[2, 0] != 0.0 or g[2, 1] != 0.0 else None


def _gravity_grid(spout: SpoutGeometry) -> np.ndarray | None:
    """Gravity (3,) m/s^2 in the cart grid frame when the cart is tilted (its IMU knows it), else None."""
    return spout[3][:3, :3] @ np.array([0.0, 0.0, -ag.GRAVITY_MPS2]) if _tilt(spout) is not None else None


def _predicted_impacts(spg: np.ndarray, vg: np.ndarray, p: ModelParams,
                       gravity: np.ndarray | None = None) -> tuple[float, tuple[float, float], tuple[float, float]]:
    """From the known geometry, the spout ``spg`` (3,) m and exit velocity ``vg`` (3,) m/s in the cart grid frame
    (``gravity`` (3,) there when the cart is tilted): (drift along grid x m, landing grid xy at the target height,
    on the floor)."""
    top = ag.landing_xy(spg, vg, p.control.target_m, gravity)
    floor = ag.landing_xy(spg, vg, 0.0, gravity)
    drift = 0.5 * (top[0] + floor[0]) - float(spg[0])
    return drift, top, floor


def step_frame(w: World, meas: np.ndarray | None, p: ModelParams) -> World:
    """Advance the world by one sensor frame acting on ``meas`` (controller grid heights m, NaN holes) or None."""
    x = w.x
    if p.fmus is not None:
        p.fmus.begin_frame(w.frame + 1)
    fs = advance_noise(w.field, p.field, w.frame + 1) if p.field is not None else None
    # the controller aims with the relative pose the GNSS receivers give (the truth without their error)
    seen = w.spout if fs is None or p.field.gnss[0] == 0.0 else spout_grid(np.array(measured_state(x, fs.gnss)), p)
    _, vel, spg, g = seen
    vg = g[:3, :3] @ vel
    gravity = _gravity_grid(seen)
    drift, top, floor = _predicted_impacts(spg, vg, p, gravity)
    signal = w.setpoint[0] + p.signal_offset_m
    delivery = Delivery(w.delivered_m3 * (1.0 + p.flow_meter_bias), spg, vg, gravity)
    # the stream lands between these two points: both must be safely inside
    shifts, lateral = _turn_feedforward(w, p)
    inp = ControllerInput(w.t_s, w.frame, meas, float(spg[0]), (top, floor), drift, signal, delivery,
                          p.control.target_m, shifts, lateral, speed_change(p.field, w.t_s, p.control.safety_lead_s))
    ctrl, out = _decide(w, inp, p)
    setpoint = (w.setpoint[0] + out.nudge * p.control.nudge_m, w.setpoint[1])
    if fs is not None and p.field.moves_vehicles and (p.fmus is None or p.fmus.vehicle is None):
        x, fs = advance_vehicles(x, (setpoint[0], setpoint[1] + out.lateral_m), fs, p.field, p.vehicles, p.gains,
                                 Stepping(p.method, p.dt_s, p.steps, p.rtol, p.atol), w.t_s)
    else:
        x = _advance_vehicles(x, (setpoint[0], setpoint[1] + out.lateral_m), p, w.frame + 1)
    level, vol = _flow(w.flow_level, out, p, fs)
    if fs is not None:
        fs = replace(fs, since_start_s=_since_start(w.flow_level, level, fs.since_start_s, p.frame_dt_s))
    spout = spout_grid(x, p)
    h, spill, spill_outside = w.heights, 0.0, 0.0
    tilt = _tilt(spout)
    if tilt is not None:                             # the cart moved to a new tilt: the pile settles first
        cap = tilted_cap(p.grid, tilt)
        h, spill = settle(h, p.grid, tilt, cap)
    imp, rows, n = _stream(spout, h, level, vol > 0.0 or level > 0.0, p)
    if vol > 0.0:
        if imp.surface != ag.SURFACE_GRAIN:
            spill_outside = vol
        elif tilt is None:
            h, spill = deposit(h, float(imp.grid[0]), float(imp.grid[1]), vol, p.grid, p.cap)
        else:
            h, deposit_spill = deposit_tilted(h, float(imp.grid[0]), float(imp.grid[1]), vol, p.grid, tilt, cap)
            spill += deposit_spill
    return World(w.frame + 1, (w.frame + 1) * p.frame_dt_s, x, level, h, w.initial_m3, w.delivered_m3 + vol,
                 w.spilled_m3 + spill + spill_outside, w.spilled_outside_m3 + spill_outside, setpoint, ctrl, out, imp,
                 rows, n, spout, w.nudges + (out.nudge != 0), fs)


def _flow(level: float, out: ControllerCommand, p: ModelParams, fs: FieldState | None) -> tuple[float, float]:
    """(flow level, volume delivered m^3) over the frame: the auger's ramps step by step, times the field's
    flow factor (the yield variation and the start surge, dynamics_proc.vehicles.fieldsync) where there is one."""
    vol = 0.0
    for _ in range(p.steps):
        level, dv = ag.flow_advance(level, out.auger_on, p.dt_s, p.auger, out.flow)
        vol += dv
    return level, (vol * flow_factor(p.field, fs) if fs is not None else vol)


def _since_start(before: float, after: float, since: float, dt: float) -> float:
    """Time since the flow last started (s): 0 where it starts this frame, else one frame more."""
    return 0.0 if before == 0.0 and after > 0.0 else since + dt


def _turn_feedforward(w: World, p: ModelParams) -> tuple[tuple[float, float], float]:
    """((now, ahead) spout shifts along grid x m, lateral setpoint correction m ahead) of the combine's turn at
    ``w.t_s`` and ``feedforward_lead_s`` later (dynamics_proc.control.feedforward); ((0, 0), 0) on a straight path."""
    now, ahead = (combine_motion(p.field, p.vehicles, t) for t in (w.t_s, w.t_s + p.feedforward_lead_s))
    if now[1] == 0.0 and ahead[1] == 0.0:
        return (0.0, 0.0), 0.0
    spout = np.add(p.auger.pivot, p.auger.arm)
    out = [turn_compensation(wr, w.setpoint, replace(p.vehicles, combine_speed_mps=v), spout, p.grid_from_cart_body)
           for v, wr in (now, ahead)]
    return (out[0][1], out[1][1]), out[1][0]


def _decide(w: World, inp: ControllerInput, p: ModelParams) -> tuple[object, ControllerCommand]:
    """The controller's (state, checked command) at ``w``; a plug-in that raises or returns a bad value ends the
    run with a PluginFault naming it and the frame being stepped to."""
    frame = w.frame + 1
    try:
        result = p.controller.step(w.ctrl, inp)
    except PluginFault as e:
        raise e.at_frame(frame) from e.__cause__
    except Exception as e:  # noqa: BLE001 - a plug-in's failure is reported with its name
        raise PluginFault(p.controller_ref, CONTROLLER_POINT, f"step raised {type(e).__name__}: {e}", frame) from e
    if not isinstance(result, tuple) or len(result) != 2:
        raise PluginFault(p.controller_ref, CONTROLLER_POINT, f"step returned {type(result).__name__}, expected "
                          "(state, ControllerCommand)", frame)
    try:
        return result[0], check_command(result[1], p.control.sections, p.controller_ref)
    except PluginFault as e:
        raise e.at_frame(frame) from None


def _advance_vehicles(x: np.ndarray, setpoint: tuple[float, float], p: ModelParams, frame: int) -> np.ndarray:
    """The vehicle state (9,) at the end of frame ``frame``: ``p.steps`` steps of ``p.dt_s``, each with the Machine
    Sync input held (or the FMU vehicle's steps). The exponential method keeps the state as Python floats between
    the steps (same bits)."""
    if p.fmus is not None and p.fmus.vehicle is not None:
        return p.fmus.vehicle.advance(x, setpoint, frame, p.vehicles, p.gains)
    if p.method == "exponential":
        xs = x.tolist()
        for _ in range(p.steps):
            xs = step_exponential_values(xs, sync_command(xs, setpoint, p.vehicles, p.gains), p.vehicles, p.dt_s)
        return np.array(xs)
    for _ in range(p.steps):
        x = integrate(p.method, x, sync_command(x, setpoint, p.vehicles, p.gains), p.vehicles, p.dt_s, 1, p.rtol,
                      p.atol)
    return x

