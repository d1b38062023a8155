"""Machine Sync and the flow in a field (docs/field.md): GNSS error, radio latency, actuation delay, the combine's
speed and turn profile, wheel slip, yield-driven flow and the auger's start surge.

Pure functions over :class:`FieldParams` (from the scenario, None when every condition is off: the frame step
then runs its ideal code unchanged) and :class:`FieldState` (carried in the world from frame to frame):

* per frame, the Gauss-Markov processes (dynamics_proc.vehicles.fieldnoise) step once: each GNSS receiver's horizontal
  error (combine and tractor, x and y), the slip, the flow's relative variation;
* per dynamics step, :func:`advance_vehicles`: the combine moves with the profile's speed and curvature at the
  step's start (held over the step, as every input); the tractor's Machine Sync law (dynamics_proc.vehicles.machine_sync)
  sees the combine's pose ``radio_latency_s`` old (extrapolated over the delay along the arc of the speed and yaw
  rate it came with, with ``latency_compensation``) and both positions with their receivers' errors, and its
  command reaches the drivetrain and steering ``actuation_delay_s`` later; the tractor's ground speed is its
  wheel speed times (1 - slip).

The controller aims with the relative pose the receivers give (:func:`measured_state`): a GNSS error moves the
spout it believes it sees over the cart.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from cosim.scenario.config import Scenario
from dynamics_proc.vehicles.fieldnoise import (
    FLOW_STREAM,
    GNSS_STREAM,
    SLIP_STREAM,
    draws,
    gm_coefficients,
    gm_start,
    gm_step,
)
from dynamics_proc.vehicles.integrators import Stepping, integrate, step_exponential_values
from dynamics_proc.vehicles.machine_sync import SyncGains, sync_command
from dynamics_proc.vehicles.motion import CX, CY, CYAW, DELTA, TX, TY, V, VehicleParams, combine_advance

__all__ = ["FieldParams", "FieldState", "initial_field", "advance_noise", "combine_motion", "measured_state",
           "advance_vehicles", "flow_factor", "speed_change", "SLIP_MAX"]

#: slip is clipped to [0, SLIP_MAX]
SLIP_MAX = 0.5


@dataclass(frozen=True)
class FieldParams:
    """The scenario's field conditions (SI), derived once. Processes: (sigma, phi, q) per frame."""

    seed: int
    profile: tuple[tuple[float, float, float], ...]   # (t s, speed m/s, curvature 1/m) points, () none
    gnss: tuple[float, float, float]
    latency_steps: int
    compensate: bool
    delay_steps: int
    slip_mean: float
    slip: tuple[float, float, float]
    flow: tuple[float, float, float]
    surge: float
    surge_tau_s: float

    @property
    def moves_vehicles(self) -> bool:
        """Whether the vehicles' steps need this module (else the ideal loop runs, to the bit)."""
        return bool(self.profile or self.gnss[0] > 0.0 or self.latency_steps or self.delay_steps
                    or self.slip_mean > 0.0 or self.slip[0] > 0.0)

    @classmethod
    def from_scenario(cls, s: Scenario) -> "FieldParams | None":
        """The field conditions of ``s``, None when none is on."""
        ms, a, t = s.machine_sync, s.auger, s.tractor
        frame, dt = s.timing.sensor_period_s, s.timing.dynamics_dt_s

        def process(sigma: float, tau: float) -> tuple[float, float, float]:
            return (sigma, *gm_coefficients(sigma, tau, frame))

        fp = cls(s.seed, tuple((p.t_s, p.speed_mps, p.curvature_1pm) for p in s.combine.profile),
                 process(ms.gnss.sigma, ms.gnss.correlation_time_s), round(ms.radio_latency_s / dt),
                 ms.latency_compensation, round(ms.actuation_delay_s / dt), t.slip.mean,
                 process(t.slip.sigma, t.slip.correlation_time_s),
                 process(a.flow_variation.sigma, a.flow_variation.correlation_time_s), a.start_surge,
                 a.start_surge_tau_s)
        on = fp.moves_vehicles or fp.flow[0] > 0.0 or fp.surge > 0.0
        return fp if on else None


@dataclass(frozen=True)
class FieldState:
    """The field conditions' memory: ``gnss`` (4,) m (combine x, y, tractor x, y errors, world axes), ``slip``
    (fraction), ``flow_variation`` (relative), ``since_start_s`` (time since the flow last started, s; inf
    never), ``history``: the combine's (x, y, yaw, speed, yaw rate) of the last ``latency_steps + 1`` steps,
    oldest first; ``commands``: the tractor's commands (v m/s, steer rad) still on their way, oldest first."""

    gnss: np.ndarray
    slip: float
    flow_variation: float
    since_start_s: float
    history: tuple
    commands: tuple


def combine_motion(fp: FieldParams | None, vp: VehicleParams, t_s: float) -> tuple[float, float]:
    """The combine's (speed m/s, yaw rate rad/s) at ``t_s``: the profile's, linear between its points, or the
    scenario's constant ones."""
    if fp is None or not fp.profile:
        return vp.combine_speed_mps, vp.combine_yaw_rate_radps
    pts = fp.profile
    if t_s <= pts[0][0]:
        v, k = pts[0][1], pts[0][2]
    elif t_s >= pts[-1][0]:
        v, k = pts[-1][1], pts[-1][2]
    else:
        i = next(i for i in range(1, len(pts)) if pts[i][0] > t_s)
        (t0, v0, k0), (t1, v1, k1) = pts[i - 1], pts[i]
        f = (t_s - t0) / (t1 - t0)
        v, k = v0 + f * (v1 - v0), k0 + f * (k1 - k0)
    return v, v * k


def speed_change(fp: FieldParams | None, t_s: float, window_s: float) -> float:
    """The largest rate of change of the combine's profile speed over [t_s, t_s + window_s], m/s^2 (0 without
    a profile): the steepest of the profile's segments that overlap the window."""
    if fp is None or len(fp.profile) < 2:
        return 0.0
    out = 0.0
    for (t0, v0, _), (t1, v1, _) in zip(fp.profile, fp.profile[1:]):
        if t1 > t_s and t0 < t_s + window_s:
            out = max(out, abs(v1 - v0) / (t1 - t0))
    return out


def _slip(fp: FieldParams, dev: float) -> float:
    return min(max(fp.slip_mean + dev, 0.0), SLIP_MAX)


def initial_field(fp: FieldParams, x: np.ndarray, vp: VehicleParams, dt: float) -> FieldState:
    """Frame 0: the processes drawn from their stationary distributions; the history of the combine's poses the
    ``latency_steps`` steps of ``dt`` s before (driving as at t = 0); the command pipe full of the start
    command."""
    v, w = combine_motion(fp, vp, 0.0)
    start = replace(vp, combine_speed_mps=v, combine_yaw_rate_radps=w)
    # the poses the radio carried before t = 0: the combine was already driving so
    hist = tuple((*combine_advance(float(x[CX]), float(x[CY]), float(x[CYAW]), start, -k * dt), v, w)
                 for k in range(fp.latency_steps + 1, 0, -1))      # t = -(L + 1) dt .. -dt: each step appends
    s = FieldState(gm_start(fp.gnss[0], draws(fp.seed, GNSS_STREAM, 0, 4)),
                   float(gm_start(fp.slip[0], draws(fp.seed, SLIP_STREAM, 0, 1))[0]),
                   float(gm_start(fp.flow[0], draws(fp.seed, FLOW_STREAM, 0, 1))[0]), math.inf, hist, ())
    # the commands on their way at t = 0 are those that held the tractor at its speed and steering before
    return replace(s, commands=((float(x[V]), float(x[DELTA])),) * fp.delay_steps)


def advance_noise(s: FieldState, fp: FieldParams, frame: int) -> FieldState:
    """The processes one frame on (the draws of ``frame``)."""
    return replace(s, gnss=gm_step(s.gnss, fp.gnss[1], fp.gnss[2], draws(fp.seed, GNSS_STREAM, frame, 4)),
                   slip=float(gm_step(s.slip, fp.slip[1], fp.slip[2], draws(fp.seed, SLIP_STREAM, frame, 1))[0]),
                   flow_variation=float(gm_step(s.flow_variation, fp.flow[1], fp.flow[2],
                                                draws(fp.seed, FLOW_STREAM, frame, 1))[0]))


def measured_state(x, gnss: np.ndarray) -> list[float]:
    """The vehicle state (as a list) with the combine's and the tractor's positions as their receivers give
    them (``gnss`` (4,) m errors)."""
    xs = list(x.tolist() if isinstance(x, np.ndarray) else x)
    e = gnss.tolist()
    xs[CX] += e[0]
    xs[CY] += e[1]
    xs[TX] += e[2]
    xs[TY] += e[3]
    return xs


def flow_factor(fp: FieldParams | None, s: FieldState | None) -> float:
    """The flow's multiplier now: 1 + the yield variation + the start surge, at least 0 (1.0 without both)."""
    if fp is None or s is None:
        return 1.0
    surge = fp.surge * math.exp(-s.since_start_s / fp.surge_tau_s) if fp.surge > 0.0 else 0.0
    return max(1.0 + s.flow_variation + surge, 0.0)


def _received(fp: FieldParams, s_hist: tuple, vp: VehicleParams, dt: float) -> tuple[list[float], VehicleParams]:
    """The combine's pose as the tractor has it (latency, and its extrapolation) and the motion it came with."""
    cx, cy, cyaw, v, w = s_hist[0]
    vr = replace(vp, combine_speed_mps=v, combine_yaw_rate_radps=w)
    if fp.compensate and fp.latency_steps:
        cx, cy, cyaw = combine_advance(cx, cy, cyaw, vr, fp.latency_steps * dt)
    return [cx, cy, cyaw], vr


def advance_vehicles(x: np.ndarray, setpoint: tuple[float, float], s: FieldState, fp: FieldParams, vp: VehicleParams,
                     gains: SyncGains, stepping: Stepping, t0: float) -> tuple[np.ndarray, FieldState]:
    """The vehicle state (9,) ``stepping.steps`` steps of ``stepping.dt_s`` on from time ``t0`` in the field (the
    module docstring), and the field state with its history and command pipe moved on."""
    method, dt, steps, rtol, atol = stepping.method, stepping.dt_s, stepping.steps, stepping.rtol, stepping.atol
    xs = x.tolist()
    hist, cmds = s.history, s.commands
    keep = 1.0 - _slip(fp, s.slip)
    for k in range(steps):
        t = t0 + k * dt
        v, w = combine_motion(fp, vp, t)
        hist = hist[1:] + ((xs[CX], xs[CY], xs[CYAW], v, w),)
        pose, vr = _received(fp, hist, vp, dt)
        seen = measured_state(pose + xs[3:], s.gnss)
        u = sync_command(seen, setpoint, vr, gains)
        if fp.delay_steps:
            cmds, u = cmds[1:] + (u,), cmds[0]
        vt = replace(vp, combine_speed_mps=v, combine_yaw_rate_radps=w, ground_keep=keep)
        if method == "exponential":
            xs = step_exponential_values(xs, u, vt, dt)
        else:
            xs = integrate(method, np.array(xs), u, vt, dt, 1, rtol, atol).tolist()
    return np.array(xs), replace(s, history=hist, commands=cmds)
