"""Offloading controller: section fullness from a (possibly perceived) height map, target section, desired
auger location, nudges of the Machine Sync setpoint, auger on/off and flow.

Runs once per sensor frame on the measurement the latency rule gives it (or none). Positions are along the
cart grid x axis (m from the front inner wall, increasing to the rear). The four signals of the paper's
Fig 9, all in that coordinate:

* desired auger location: the target section's centre, less the predicted ballistic drift of the impact
  along x, clipped to the safe range;
* control effort (continuous): desired + b, where b is the slowly filtered steady-state difference between
  where the setpoint should put the spout and where it is (zero on a straight path; compensates off-tracking),
  less the turn's predicted shift with ``controller.coping.feedforward``;
* nudge (actuating) signal: the spout location the nudged setpoint implies; it moves in steps of ``nudge_m``
  no more often than ``nudge_min_interval_s``, towards the control effort, never into the unsafe range;
* actual auger location: the spout, measured.

Measurements: a height map (nxc, nyc) m on the controller grid, NaN where invalid, or None (an all-NaN map
counts as none). Section heights are the highest NaN-ignoring 2 x 2 block minimum (a robust peak: one noisy
cell cannot fake it); sections without a valid cell keep their last value. A section counts as full once its
estimate reaches the full level, and stays full (latched: noise must not send the auger back). With the
paper's estimator a target section without a valid cell for ``stale_timeout_s`` while the auger runs is given
up as full; the fused estimator instead fills on by dead reckoning while its stated confidence lasts. The auger
runs only while there is a target within TRAVEL_ON_SECTIONS section lengths of the predicted impact (it
travels farther with the auger off), the predicted impact is safely inside the cart, a measurement has been
seen and the controller is not holding.

Coping with field conditions (``controller.coping``, dynamics_proc.control.coping): the auger is slowed to
``slow_flow`` once a section's level plus its measured rise over ``full_lead_s`` reaches the full level while
that rise exceeds ``lead_allowance_m`` (a high flow), and stays slowed until the impact has travelled into the
next target; when the target section is not seen the fused estimate carries on while its 1-sigma stays within
``fallback_sigma_m``, beyond it the auger is switched off and the controller holds, saying why
(``hold_reason``); the spout keeps moving to the target meanwhile (with the auger off that is safe, and it may
bring the cart back into view); with ``feedforward`` the lateral setpoint and the auger target anticipate the
cart's off-tracking in a turn (dynamics_proc.control.feedforward).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from cosim.errors import PluginFault
from cosim.scenario.config import Scenario
from cosim.scenario.plugins import load_plugin
from dynamics_proc.control.coping import (
    SlowLimits,
    mode,
    peak_sigma,
    rise_rate,
    slowed_section,
    unexplained_shift,
)
from dynamics_proc.control.estimator import (
    FillEstimate,
    FusionParams,
    consistent,
    initial_estimate,
    landing_on,
    predict,
    update,
)
from dynamics_proc.control.flowlead import commanded_level, level_filter, rise_at_nominal
from dynamics_proc.control.protocol import HOLD_NO_MEASUREMENT, ControllerCommand, ControllerInput, Delivery
from dynamics_proc.control.sections import min2x2, section_blocks, section_heights, section_pairing, section_valid
from dynamics_proc.control.strategies import Strategy
from dynamics_proc.grain.fill import GrainGrid, section_rows

__all__ = ["BIAS_TAU_S", "SETTLE_S", "STRATEGY_POINT", "ControllerParams", "ControllerState", "Delivery",
           "min2x2", "section_heights", "section_valid", "initial_controller", "Ingested", "Fullness", "Aim", "ingest",
           "fullness", "aim", "safety", "controller_step",
           "SectionFillController", "plugin_dir"]

#: the scenario key of the fill strategy plug-in (named in faults)
STRATEGY_POINT = "controller.strategy"

#: time constant of the steady-state bias filter, s
BIAS_TAU_S = 5.0
#: the bias is only learnt this long after the last nudge (transients excluded), s
SETTLE_S = 6.0
#: the auger keeps running while the target is within this many section lengths (adjacent moves, allowing
#: for the nudge lattice); farther targets are approached with the auger off
TRAVEL_ON_SECTIONS = 1.5
#: slack on the nudge threshold (half a nudge) so that an exactly half-way error does not chatter, m
NUDGE_SLACK_M = 1e-9


@dataclass(frozen=True)
class ControllerParams:
    """Controller constants (SI), derived from the scenario."""

    target_m: float
    full_level_m: float
    sections: int
    length_m: float
    width_m: float
    grid_cell_m: float
    nx: int
    ny: int
    section_start_rows: tuple[int, ...]
    edge_cells: tuple[int, int]      # rows / columns left out at each wall
    min_section_cells: int
    centres_m: tuple[float, ...]
    safe_margin_m: float
    off_margin_m: float
    nudge_m: float
    nudge_interval_s: float
    stale_timeout_s: float
    estimator: str
    strategy: Strategy               # the fill strategy (controller.strategy, loaded: a built-in or a plug-in)
    frame_dt_s: float
    fusion: FusionParams | None      # the fused estimator's constants (estimator "fused"), else None
    strategy_ref: str = ""           # controller.strategy as the scenario names it
    full_lead_s: float = 0.0         # controller.coping: lead on the full level (0: none), s
    rise_tau_s: float = 0.5          # time constant of the rise-rate filter, s
    fallback_sigma_m: float = math.inf  # dead reckoning goes on while the target's 1-sigma stays at most this, m
    feedforward: bool = False        # add the turn's predicted spout shift (ControllerInput.turn_shift_m)
    slow_flow: float = 1.0           # commanded flow fraction once a section is near full (1: never slowed)
    safety_lead_s: float = 0.0       # the impact is checked this far ahead at the spout's unexplained velocity, s
    pause_accel_mps2: float = math.inf  # the auger pauses while the combine's speed changes faster, m/s^2
    nudge_speed_mps: float = math.inf  # the spout's speed over the cart a nudge explains, m/s
    overfull_margin_m: float = math.inf  # no grain on a section other than the target this far over the target, m
    lead_allowance_m: float = 0.0    # a rise over the lead up to this needs no slowing, m
    lead_at_nominal: bool = False    # judge a released-onto target's lead at the nominal flow (control.flowlead)

    @classmethod
    def from_scenario(cls, s: Scenario, strategy: Strategy | None = None) -> "ControllerParams":
        """The constants of ``s``; ``strategy``: the fill strategy when it is not loaded by its name (an FMU's,
        dynamics_proc.fmu.models)."""
        c, k = s.controller, s.cart
        cell = c.grid_cell_m
        nx, ny = k.grid_shape(cell)
        rows = section_rows(nx, cell, k.interior_length_m, c.sections)
        counts = np.bincount(rows, minlength=c.sections)
        if np.any(counts == 0):
            raise ValueError(f"controller grid ({nx} cells of {cell} m along x) leaves sections without a cell; "
                             f"use fewer than {c.sections} sections or a finer controller.grid_cell_m")
        if strategy is None:
            strategy = load_plugin("strategies", c.strategy, base_dir=plugin_dir(s), options=c.strategy_options)
        sl = k.interior_length_m / c.sections
        return cls(c.target_fill_m, c.full_fraction * c.target_fill_m, c.sections, k.interior_length_m,
                   k.interior_width_m, cell, nx, ny, tuple(int(np.searchsorted(rows, i)) for i in range(c.sections)),
                   _edge_cells(c.edge_margin_m, cell, nx, ny), c.min_section_cells,
                   tuple((i + 0.5) * sl for i in range(c.sections)), c.safe_margin_m,
                   max(c.safe_margin_m - c.safety_hysteresis_m, 0.0), s.machine_sync.nudge_m,
                   s.machine_sync.nudge_min_interval_s, c.stale_timeout_s, c.estimator, strategy,
                   s.timing.sensor_period_s, _fusion(s, nx, ny) if c.estimator == "fused" else None, c.strategy,
                   full_lead_s=c.coping.full_lead_s, rise_tau_s=c.coping.rise_tau_s,
                   fallback_sigma_m=c.coping.fallback_sigma_m, feedforward=c.coping.feedforward,
                   slow_flow=c.coping.slow_flow, lead_allowance_m=c.coping.lead_allowance_m,
                   lead_at_nominal=c.coping.lead_at_nominal_flow,
                   safety_lead_s=c.coping.safety_lead_s,
                   pause_accel_mps2=c.coping.pause_accel_mps2 if c.coping.pause_accel_mps2 > 0.0 else math.inf,
                   nudge_speed_mps=s.machine_sync.kp_long * s.machine_sync.nudge_m,
                   overfull_margin_m=c.coping.overfull_margin_m)


def plugin_dir(s: Scenario) -> Path | None:
    """The folder the scenario's plug-ins are looked for first (``Scenario.plugin_dir``), None for none."""
    return Path(s.plugin_dir) if s.plugin_dir else None


def _fusion(s: Scenario, nx: int, ny: int) -> FusionParams:
    f = s.controller.fusion
    grid = GrainGrid(nx, ny, s.controller.grid_cell_m, s.cart.interior_depth_m, math.tan(s.crop.repose_rad),
                     s.grain.deposit_radius_m)
    return FusionParams(grid, f.flow_sigma, f.settle_sigma_m, f.measurement_sigma_m, s.timing.latency_frames,
                        f.gate_sigma, f.gate_share)


def _edge_cells(margin_m: float, cell_m: float, nx: int, ny: int) -> tuple[int, int]:
    """Rows / columns whose centres lie within ``margin_m`` of a wall: (i + 0.5) cell < margin. Never so many
    that nothing is left."""
    k = max(0, math.ceil(margin_m / cell_m - 0.5))
    return min(k, (nx - 1) // 2), min(k, (ny - 1) // 2)


@dataclass(frozen=True)
class ControllerState:
    """Controller memory between frames."""

    heights: np.ndarray          # (N,) m, last estimate per section, NaN never measured
    last_valid_t: np.ndarray     # (N,) s, time of the last valid cell per section (-inf never)
    forced_full: np.ndarray      # (N,) bool, sections given up as stale
    full: np.ndarray             # (N,) bool, sections declared full (latched)
    estimate: FillEstimate | None  # the fused estimate (estimator "fused"), else None
    delivered_m3: float          # flow signal integrated up to the last step, m^3
    target: int                  # 0-based section being filled, -1 none
    last_nudge_t: float          # s
    bias_m: float
    auger_cmd: bool
    seen: bool                   # a measurement has arrived
    all_full: bool
    nudges: int
    rate: np.ndarray | None = None  # (N,) m/s, filtered rise rate of each section's peak (coping)
    hold: int = 0                # hold reason code (dynamics_proc.control.protocol.HOLD_*), 0 not holding
    slowed: int = -1             # 0-based section the auger is slowed for (near full), -1 none
    spout_x: float = math.nan    # the spout's grid x at the last decision, m
    level_f: float = 0.0         # commanded flow level, filtered as the rise rate is (control.flowlead)


def initial_controller(p: ControllerParams) -> ControllerState:
    """State before the first measurement: nothing known, auger off."""
    n = p.sections
    est = initial_estimate(p.fusion) if p.fusion is not None else None
    return ControllerState(heights=np.full(n, np.nan), last_valid_t=np.full(n, -np.inf), forced_full=np.zeros(n, bool),
                           full=np.zeros(n, bool), estimate=est, delivered_m3=0.0, target=-1, last_nudge_t=-np.inf,
                           bias_m=0.0, auger_cmd=False, seen=False, all_full=False, nudges=0, rate=np.zeros(n),
                           hold=HOLD_NO_MEASUREMENT)


def _inside(x: float, y: float, margin: float, p: ControllerParams) -> bool:
    return margin <= x <= p.length_m - margin and margin <= y <= p.width_m - margin


@dataclass(frozen=True)
class Ingested:
    """What a decision knows after taking in the frame's inputs (:func:`ingest`): per-section ``heights`` (N,) m
    (NaN unknown), ``last_valid_t`` (N,) s, ``seen``, the fused ``estimate`` and ``delivered_m3`` it has taken in,
    ``ok`` (N,) bool the sections the measurement covered (None: no measurement used), and ``blocks`` the started
    estimate's 2 x 2 block minima (:func:`section_blocks`, else None)."""

    heights: np.ndarray
    last_valid_t: np.ndarray
    seen: bool
    estimate: FillEstimate | None
    delivered_m3: float
    ok: np.ndarray | None
    blocks: tuple[np.ndarray, np.ndarray] | None


@dataclass(frozen=True)
class Fullness:
    """The sections' state after :func:`fullness`: the filtered ``rate`` (N,) m/s, ``forced`` and ``full`` (N,) bool,
    the ``target`` (-1 none), ``all_full``, the ``slowed`` section (-1 none), the ``mode``, the ``hold`` reason and
    the target's 1-sigma ``sigma_m``."""

    rate: np.ndarray
    forced: np.ndarray
    full: np.ndarray
    target: int
    all_full: bool
    slowed: int
    mode: int
    hold: int
    sigma_m: float


@dataclass(frozen=True)
class Aim:
    """Where the spout should be (:func:`aim`): ``desired_m`` (grid x), the learnt ``bias_m``, the bias with the
    turn ahead ``total_bias_m``, the ``effort_m`` (desired + total bias), the ``nudge`` (-1, 0, 1), the time of the
    last nudge ``last_nudge_t`` (s) and the ``nudges`` so far."""

    desired_m: float
    bias_m: float
    total_bias_m: float
    effort_m: float
    nudge: int
    last_nudge_t: float
    nudges: int


def ingest(st: ControllerState, p: ControllerParams, inp: ControllerInput) -> Ingested:
    """Stage 1: the fused estimate predicted with the grain delivered since the last decision, and the measurement
    (``inp.heights``, rejected whole when the fused estimate finds it inconsistent) taken in."""
    heights, last_valid, seen = st.heights, st.last_valid_t, st.seen
    est, delivered = st.estimate, st.delivered_m3
    meas, delivery = inp.heights, inp.delivery
    if est is not None:
        if delivery is None:
            raise ValueError("the fused estimator needs the delivery signal")
        vol = max(delivery.delivered_m3 - delivered, 0.0)
        delivered = delivery.delivered_m3
        if vol > 0.0 and est.started:
            gx, gy = landing_on(est.height, delivery.spout, delivery.velocity, p.fusion.grid, delivery.gravity)
            est = predict(est, vol, gx, gy, p.fusion)
        else:
            est = predict(est, 0.0, 0.0, 0.0, p.fusion)
    ok = None
    if meas is not None and est is not None and not consistent(est, meas, p.fusion):
        meas = None                                            # rejected whole: as if nothing was seen
    if meas is not None:
        m = np.asarray(meas, dtype=np.float64)
        if est is None:
            new = section_heights(m, p)
            ok = ~np.isnan(new)
            heights = np.where(ok, new, heights)
        else:
            ok = section_valid(m, p)
            est = update(est, m, p.fusion)
        last_valid = np.where(ok, inp.t_s, last_valid)
        seen = seen or bool(ok.any())                          # an all-NaN map is no measurement
    # the estimate's 2 x 2 block minima: its section peaks and the target's sigma read them
    blocks = section_blocks(est.height, p) if est is not None and est.started else None
    if blocks is not None:
        heights = section_heights(est.height, p, blocks)
    return Ingested(heights=heights, last_valid_t=last_valid, seen=seen, estimate=est, delivered_m3=delivered, ok=ok,
                    blocks=blocks)


def fullness(st: ControllerState, p: ControllerParams, inp: ControllerInput, ing: Ingested) -> Fullness:
    """Stage 2: the sections' rise rates, which are full (latched; a stale target given up as full with the paper's
    estimator), the strategy's target, whether the auger is slowed, and the mode and hold reason."""
    heights, seen = ing.heights, ing.seen
    rate = st.rate if st.rate is not None else np.zeros(p.sections)
    if p.full_lead_s > 0.0:
        rate = rise_rate(rate, st.heights, heights, p.frame_dt_s, p.rise_tau_s)
    forced = st.forced_full
    # the paper's estimator has nothing to go on without a view: a target stale for long is given up as full.
    # The fused one carries on by dead reckoning while its confidence lasts (below)
    if (ing.estimate is None and seen and st.target >= 0 and st.auger_cmd
            and inp.t_s - ing.last_valid_t[st.target] > p.stale_timeout_s and not forced[st.target]):
        forced = forced.copy()
        forced[st.target] = True
    with np.errstate(invalid="ignore"):
        full = (heights >= p.full_level_m) | forced      # NaN (unknown) is not full
    full |= st.full                                       # latched: grain does not leave the cart
    target = _pick(p, full, heights, st.target) if seen else -1
    lead_rate = rise_at_nominal(rate, st.level_f, st.slowed, target, p.slow_flow) if p.lead_at_nominal else rate
    slowed = slowed_section(target, st.slowed, full, heights, lead_rate, inp.spout_x_m + inp.drift_x_m,
                            SlowLimits(p.full_lead_s, p.lead_allowance_m, p.full_level_m, p.centres_m,
                                       p.length_m / p.sections))
    mode_, hold, sigma = _mode(p, seen, target, ing.ok, ing.estimate, ing.blocks)
    return Fullness(rate=rate, forced=forced, full=full, target=target, all_full=seen and target < 0, slowed=slowed,
                    mode=mode_, hold=hold, sigma_m=sigma)


def aim(st: ControllerState, p: ControllerParams, inp: ControllerInput, target: int) -> Aim:
    """Stage 3: the desired spout position over ``target`` (inside the safe margins), the steady-state bias learnt
    while settled (with the turn's feed-forward), and a nudge of the Machine Sync setpoint when the effort is half a
    nudge away and the predicted impact after it stays inside."""
    t, actual_x, drift_x, signal = inp.t_s, inp.spout_x_m, inp.drift_x_m, inp.nudge_signal_m
    lo, hi = p.safe_margin_m, p.length_m - p.safe_margin_m
    if target >= 0:
        desired = min(max(p.centres_m[target] - drift_x, lo - drift_x), hi - drift_x)
    else:
        desired = actual_x
    now_shift, ahead_shift = inp.turn_shift_m if p.feedforward else (0.0, 0.0)
    bias = st.bias_m
    if t - st.last_nudge_t >= SETTLE_S:
        bias += (p.frame_dt_s / BIAS_TAU_S) * ((signal - actual_x + now_shift) - bias)
    total_bias = bias - ahead_shift
    effort = desired + total_bias
    nudge, last_nudge, count = 0, st.last_nudge_t, st.nudges
    err = effort - signal
    if (target >= 0 and t - st.last_nudge_t >= p.nudge_interval_s
            and abs(err) >= 0.5 * p.nudge_m - NUDGE_SLACK_M):
        step = 1 if err > 0 else -1
        landing = signal + step * p.nudge_m - total_bias + drift_x  # predicted impact x after the nudge
        if lo <= landing <= hi:
            nudge, last_nudge, count = step, t, count + 1
    return Aim(desired_m=desired, bias_m=bias, total_bias_m=total_bias, effort_m=effort, nudge=nudge,
               last_nudge_t=last_nudge, nudges=count)


def safety(st: ControllerState, p: ControllerParams, inp: ControllerInput, ing: Ingested, fill: Fullness) -> bool:
    """Stage 4: whether the auger runs: a target seen and near (travel with the auger off: grain dropped far from
    the target lands on sections that may be full), every predicted impact inside the margin (the hysteresis margin
    while running) now and at the spout's unexplained velocity ahead, the combine's speed steady enough, no
    section other than the target overfull under the impact, and no hold."""
    actual_x, target = inp.spout_x_m, fill.target
    margin = p.off_margin_m if st.auger_cmd else p.safe_margin_m
    ahead = unexplained_shift(actual_x, st.spout_x, p.frame_dt_s, p.nudge_speed_mps, p.safety_lead_s)
    safe = all(_inside(ix, iy, margin, p) and _inside(ix + ahead, iy, margin, p) for ix, iy in inp.impacts)
    safe = safe and inp.speed_change_mps2 <= p.pause_accel_mps2 and not _over_overfull(
        p, ing.heights, target, actual_x + inp.drift_x_m)
    reach = TRAVEL_ON_SECTIONS * p.length_m / p.sections
    near = target >= 0 and abs(actual_x + inp.drift_x_m - p.centres_m[target]) <= reach
    return bool(ing.seen and target >= 0 and safe and near and not fill.hold)


def controller_step(st: ControllerState, p: ControllerParams,
                    inp: ControllerInput) -> tuple[ControllerState, ControllerCommand]:
    """One controller decision at time ``inp.t_s`` (the protocol's :class:`ControllerInput`; its ``target_fill_m``
    is applied by :class:`SectionFillController`): :func:`ingest` -> :func:`fullness` -> :func:`aim` ->
    :func:`safety`. The fused estimator needs ``inp.delivery``."""
    ing = ingest(st, p, inp)
    fill = fullness(st, p, inp, ing)
    target, heights = fill.target, ing.heights
    where = aim(st, p, inp, target)
    auger = safety(st, p, inp, ing, fill)
    with np.errstate(invalid="ignore"):
        fullness_ = heights / p.target_m
    lead = max(float(fill.rate[target]), 0.0) * p.full_lead_s if target >= 0 else 0.0
    new_state = ControllerState(heights=heights, last_valid_t=ing.last_valid_t, forced_full=fill.forced, full=fill.full,
                                estimate=ing.estimate, delivered_m3=ing.delivered_m3, target=target,
                                last_nudge_t=where.last_nudge_t, bias_m=where.bias_m, auger_cmd=auger, seen=ing.seen,
                                all_full=fill.all_full, nudges=where.nudges, rate=fill.rate, hold=fill.hold,
                                slowed=fill.slowed, spout_x=inp.spout_x_m,
                                level_f=level_filter(st.level_f, commanded_level(auger, fill.slowed, p.slow_flow),
                                                     p.frame_dt_s, p.rise_tau_s))
    return new_state, ControllerCommand(
        nudge=where.nudge, auger_on=auger, desired_m=where.desired_m, effort_m=where.effort_m, target=target,
        fullness=fullness_, all_full=fill.all_full, seen=ing.seen, bias_m=where.total_bias_m, mode=fill.mode,
        hold_reason=fill.hold, sigma_m=fill.sigma_m, lead_m=lead, flow=p.slow_flow if fill.slowed >= 0 else 1.0,
        lateral_m=inp.lateral_correction_m if p.feedforward else 0.0)


def _over_overfull(p: ControllerParams, heights: np.ndarray, target: int, impact_x: float) -> bool:
    """Whether the predicted impact (grid x, m) lies over a section other than the target whose level is at
    least the target plus ``overfull_margin_m``."""
    k = min(max(int(impact_x / (p.length_m / p.sections)), 0), p.sections - 1)
    return k != target and bool(heights[k] >= p.target_m + p.overfull_margin_m)


def _mode(p: ControllerParams, seen: bool, target: int, ok: np.ndarray | None,
          est: FillEstimate | None, blocks: tuple[np.ndarray, np.ndarray] | None) -> tuple[int, int, float]:
    """(mode, hold reason, target section's 1-sigma m) of a decision (:func:`dynamics_proc.control.coping.mode`);
    ``blocks``: :func:`section_blocks` of the started estimate, else None."""
    sigma = math.nan
    if seen and target >= 0 and blocks is not None:
        starts = section_pairing(p.nx, p.section_start_rows)[0]
        rows = slice(int(starts[target]), int(starts[target + 1]) if target + 1 < p.sections else p.nx)
        sigma = peak_sigma(blocks[1], est.var, rows)
    seen_target = ok is not None and target >= 0 and bool(ok[target])
    return (*mode(seen, target, seen_target, est is not None, sigma, p.fallback_sigma_m), sigma)


def _pick(p: ControllerParams, full: np.ndarray, heights: np.ndarray, current: int) -> int:
    """The strategy's choice, checked: a section index in -1..N-1 (PluginFault naming the strategy otherwise)."""
    try:
        target = p.strategy(full, heights, current)
    except Exception as e:  # noqa: BLE001 - a strategy's failure ends the run with its name and cause
        raise PluginFault(p.strategy_ref, STRATEGY_POINT, f"raised {type(e).__name__}: {e}") from e
    if isinstance(target, (int, np.integer)) and not isinstance(target, bool) and -1 <= target < p.sections:
        return int(target)
    raise PluginFault(p.strategy_ref, STRATEGY_POINT, f"returned {target!r}; a strategy returns a section index "
                      f"in 0..{p.sections - 1}, or -1 when every section is full")


class SectionFillController:
    """The built-in offloading controller (``controller.model: section_fill``, the module docstring): the
    :mod:`dynamics_proc.control.protocol` adapter of the pure :func:`controller_step`, whose memory is the
    frozen :class:`ControllerState`."""

    def __init__(self, params: ControllerParams, scenario: Scenario | None = None):
        self.params = params
        #: "full" level as a fraction of the target (``controller.full_fraction``), for a target changed mid-run
        self.full_fraction = (scenario.controller.full_fraction if scenario is not None
                              else params.full_level_m / params.target_m)

    def initial_state(self) -> ControllerState:
        """Nothing known, auger off."""
        return initial_controller(self.params)

    def step(self, state: ControllerState, inp: ControllerInput) -> tuple[ControllerState, ControllerCommand]:
        """:func:`controller_step` on the protocol's input (at the input's target fill: the operator may change it)."""
        if inp.target_fill_m != self.params.target_m:
            self.params = replace(self.params, target_m=inp.target_fill_m,
                                  full_level_m=self.full_fraction * inp.target_fill_m)
        return controller_step(state, self.params, inp)
