"""Scenario sections for the grain fill model, the offloading controller and the integrator.

Owned by dynamics_proc. ``Controller.grid_cell_m`` and ``Controller.sections`` are shared with
perception_proc: the perceived height map is produced on that grid.
"""
from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from .base import Fraction, Model, NonNegFloat, Options, PluginRef, PosFloat
from .fmu import FMU_REF, Fmu

__all__ = ["Grain", "Fusion", "Coping", "Controller", "Integrator"]


class Grain(Model):
    """Grain fill model: height map over the cart floor.

    ``cell_m`` must divide the cart interior length and width. ``deposit_radius_m`` is the radius of the flat
    top of the heap the stream builds around its impact point.
    """

    cell_m: PosFloat = 0.1
    """Side of a cell of the true height map over the cart floor, m; must divide the cart interior length and
    width."""
    initial_fill_m: NonNegFloat = 1.0
    """Level of the grain above the cart floor at the start, m (at most the interior depth)."""
    deposit_radius_m: PosFloat = 0.25
    """Radius of the flat top of the heap the stream builds around its impact point, m."""


class Fusion(Model):
    """The fused estimator (``controller.estimator: fused``, dynamics_proc.control.estimator): a per-cell Kalman filter
    that deposits the delivered volume at the predicted impact with the heap law and corrects it with the
    perceived heights.

    * ``flow_sigma``: relative 1-sigma of each frame's predicted rise per cell (flow signal, heap shape,
      placement);
    * ``settle_sigma_m``: per-frame 1-sigma drift of every cell (settling the heap law does not model);
    * ``measurement_sigma_m``: 1-sigma of a perceived cell height;
    * ``flow_meter_bias``: relative error of the flow signal the estimator is given (0: calibrated), a study
      knob for model mismatch; the grain delivered is unchanged;
    * ``gate_sigma``, ``gate_share``: a perceived map is rejected whole when more than ``gate_share`` of its valid
      cells lie more than ``gate_sigma`` standard deviations (estimate and measurement together) from the
      estimate: a cart found in dust or debris, a misregistered frame. The controller then goes on by dead
      reckoning as when nothing was seen.
    """

    flow_sigma: NonNegFloat = 0.2
    """Relative 1-sigma of each frame's predicted rise per cell (flow signal, heap shape, placement)."""
    settle_sigma_m: NonNegFloat = 0.002
    """Per-frame 1-sigma drift of every cell (settling the heap law does not model), m."""
    measurement_sigma_m: PosFloat = 0.03
    """1-sigma of a perceived cell height, m."""
    flow_meter_bias: float = Field(default=0.0, ge=-0.9, le=10.0, allow_inf_nan=False)
    """Relative error of the flow signal the estimator is given (0: calibrated; -0.9 to 10); the grain delivered
    is unchanged."""
    gate_sigma: PosFloat = 5.0
    """Innovation gate of a perceived cell, in standard deviations of estimate and measurement together (a
    large value, e.g. 1e6: no gate)."""
    gate_share: Fraction = 0.5
    """A perceived map is rejected whole when more than this share of its valid cells fall outside the gate
    (0 to 1)."""


class Coping(Model):
    """How the built-in controller (``section_fill``) copes with field conditions (dynamics_proc.control.coping;
    docs/field.md).

    * ``full_lead_s``: lead on the full level. A section counts as full once its estimated peak plus its measured
      rise rate times this lead reaches the full level, so that the grain still arriving after the decision (the
      nudge to the next section, the auger's run-out) does not overfill it at a high flow; 0 switches the lead
      off;
    * ``rise_tau_s``: time constant of the filter on each section's measured rise rate, s;
    * ``fallback_sigma_m``: with the fused estimator, the controller fills on its dead-reckoned estimate (the
      delivered volume placed at the impact predicted from Machine Sync's relative pose) while the target
      section's 1-sigma stays at most this; beyond it the auger is switched off and the controller holds (no
      nudges) until a measurement brings the confidence back, and says why (``dyn_state.hold_reason``);
    * ``feedforward``: feed the steady-state off-tracking of the cart in a turn forward into the auger target
      (from the combine's known yaw rate ``feedforward_lead_s`` ahead), instead of waiting for the learnt bias;
    * ``feedforward_lead_s``: how far ahead the turn is anticipated, s;
    * ``safety_lead_s``: the auger runs only while the impact, moved on by the spout's velocity over the cart
      beyond what a nudge explains (``machine_sync.kp_long * nudge_m``) for this long, stays in the safe zone (the
      grain still in the air and in the auger's run-out lands meanwhile);
    * ``pause_accel_mps2``: the auger pauses while the combine's speed changes faster than this within the next
      ``safety_lead_s`` (Machine Sync cannot hold the offset through a stop or a start: the tractor lags or
      overshoots), 0 never;
    * ``overfull_margin_m``: the auger pauses while the predicted impact lies over a section other than the
      target whose level is at least the target plus this (the cart moved under the spout: slip, a stop).
    """

    full_lead_s: NonNegFloat = 1.0
    """Lead on the full level, s: a section counts as full once its peak plus its rise rate times this reaches
    the full level (0: no lead)."""
    slow_flow: float = Field(default=0.3, gt=0.0, le=1.0, allow_inf_nan=False)
    """Flow fraction commanded once a section is near full at a high flow, until the impact reaches the next
    target (0-1]."""
    lead_allowance_m: NonNegFloat = 0.06
    """A rise over the lead up to this needs no slowing, m."""
    lead_at_nominal_flow: bool = False
    """While a slowed section is released onto the next target, judge that target's lead at the nominal flow (its
    rise measured at the slowed flow scaled by nominal / slowed; dynamics_proc.control.flowlead) instead of the
    rise measured: a target that arrives nearly full then is slowed too. Removes the overshoot of a section near
    full when the flow comes back (high_flow), at the cost of slower fills wherever sections are slowed
    (docs/field.md)."""
    rise_tau_s: PosFloat = 2.0
    """Time constant of the filter on each section's measured rise rate, s."""
    fallback_sigma_m: PosFloat = 0.05
    """The controller fills on its dead-reckoned estimate while the target section's 1-sigma stays at most this,
    m; beyond it the auger stops and the controller holds."""
    feedforward: bool = True
    """Feed the cart's steady-state off-tracking in a turn forward into the auger target."""
    feedforward_lead_s: NonNegFloat = 2.0
    """How far ahead a turn is anticipated (from the combine's known yaw rate), s."""
    safety_lead_s: NonNegFloat = 1.2
    """The impact is checked this far ahead at the spout's velocity over the cart beyond what a nudge explains,
    s (0: only where it is now)."""
    pause_accel_mps2: NonNegFloat = 0.25
    """The auger pauses while the combine's speed changes faster than this within the next safety_lead_s, m/s^2
    (0: never)."""
    overfull_margin_m: NonNegFloat = 0.02
    """The auger pauses while the impact lies over a section other than the target whose level is at least the
    target plus this, m."""


class Controller(Model):
    """Offloading controller: operator inputs and the section grid.

    A section is full when its estimated peak height reaches ``full_fraction * target_fill_m`` (latched). The
    auger only runs while the predicted impact lies at least ``safe_margin_m`` inside every inner wall (it stops
    when it comes closer than ``safe_margin_m - safety_hysteresis_m``). A target section that gives no valid
    measurement for ``stale_timeout_s`` while it is being filled is treated as full (so nothing overfills
    blind). Cells whose centre lies within ``edge_margin_m`` of an inner wall are left out of the estimate (the
    heap's peak is never there; wall and rim returns are); a section's estimate is updated only from a map with
    at least ``min_section_cells`` valid cells in it. ``estimator``: ``fused`` (default) takes each section's
    robust peak (highest 2 x 2 block minimum) from the fused estimate of :class:`Fusion` (perceived heights
    fused with the volume delivered at the predicted impact); ``paper`` takes it from the perceived map alone,
    as the paper does.

    Plug-ins (docs/plugins.md; a scenario that names one runs its code): ``strategy`` picks the next section,
    ``front_to_back`` / ``back_to_front`` / ``lowest_first`` (dynamics_proc.control.strategies), an entry point name or
    an import path ``package.module:name``; ``model`` is the whole controller, ``section_fill`` (this one,
    dynamics_proc.control.controller) or a plug-in implementing dynamics_proc.control.protocol. ``fmu`` (for either)
    names the FMU ``fmu`` (docs/fmu.md). ``strategy_options`` / ``model_options``: keyword arguments the
    plug-in is called with (a strategy) or made with (a controller factory), checked against its signature.
    ``coping``: how the built-in controller copes with field conditions (:class:`Coping`).
    """

    target_fill_m: PosFloat = 1.9
    """Operator's target grain level above the cart floor, m (at most the interior depth)."""
    strategy: PluginRef = "front_to_back"
    """Which section to fill next: front_to_back, back_to_front, lowest_first, fmu, an entry point name or an
    import path package.module:name."""
    strategy_options: Options = {}
    """Keyword arguments the strategy plug-in is called with (checked against its signature)."""
    model: PluginRef = "section_fill"
    """The whole controller: section_fill (built in), fmu, or a plug-in implementing
    dynamics_proc.control.protocol."""
    model_options: Options = {}
    """Keyword arguments the controller factory is called with (checked against its signature)."""
    sections: int = Field(default=9, ge=1, le=64)
    """Number of sections the cart is filled in, along its length (1-64)."""
    grid_cell_m: PosFloat = 0.1
    """Side of a cell of the controller's and the perceived height map's grid, m."""
    full_fraction: Fraction = 0.995
    """A section is full when its estimated peak reaches this fraction of target_fill_m (latched)."""
    estimator: Literal["paper", "fused"] = "fused"
    """fused: perceived heights fused with the delivered volume; paper: perceived heights alone."""
    safe_margin_m: NonNegFloat = 0.3
    """The auger runs only while the predicted impact lies at least this far inside every inner wall, m."""
    safety_hysteresis_m: NonNegFloat = 0.1
    """The auger stops when the impact comes closer than safe_margin_m minus this, m."""
    stale_timeout_s: PosFloat = 10.0
    """A target section without a valid measurement for this long while it is filled counts as full, s."""
    edge_margin_m: NonNegFloat = 0.2
    """Cells whose centre lies within this distance of an inner wall are left out of the estimate, m."""
    min_section_cells: int = Field(default=4, ge=1)
    """A section's estimate is updated only from a map with at least this many valid cells in it."""
    fusion: Fusion = Fusion()
    """Parameters of the fused estimator (estimator: fused)."""
    coping: Coping = Coping()
    """How the built-in controller copes with field conditions: lead on the full level, dead reckoning and hold,
    turn feed-forward."""
    fmu: Fmu | None = None
    """The FMU named by model: fmu or strategy: fmu (path, variable mapping, parameters)."""

    @model_validator(mode="after")
    def _fmu_named(self) -> "Controller":
        users = [k for k in ("strategy", "model") if getattr(self, k) == FMU_REF]
        if users and self.fmu is None:
            raise ValueError(f"{users[0]} '{FMU_REF}' needs the FMU: give controller.fmu (path, inputs, outputs)")
        if len(users) > 1:
            raise ValueError(f"strategy and model are both '{FMU_REF}': one controller FMU plays one role (an FMU "
                             "controller picks its own sections)")
        if self.fmu is not None and not users:
            raise ValueError(f"controller.fmu is given but nothing uses it: set controller.model: {FMU_REF} (the "
                             f"whole controller) or controller.strategy: {FMU_REF} (the fill strategy)")
        return self


class Integrator(Model):
    """Integration of the continuous vehicle states inside one sensor frame.

    ``rk4``: classic fixed-step RK4; ``exponential``: the lags solved exactly (rate limits included) and the
    kinematics by RK4 on them; ``radau`` / ``bdf``: scipy ``solve_ivp`` with ``rtol`` / ``atol`` (reference).
    """

    method: Literal["rk4", "exponential", "radau", "bdf"] = "exponential"
    """rk4, exponential (lags solved exactly), radau or bdf (scipy solve_ivp, a reference)."""
    rtol: PosFloat = 1e-8
    """Relative tolerance of radau / bdf."""
    atol: PosFloat = 1e-10
    """Absolute tolerance of radau / bdf."""
