"""An offloading controller as an FMU (FMI 2.0 co-simulation), written with pythonfmu: the paper's section-fill
logic (front-to-back), the same decisions as graincosim's built-in controller with ``estimator: paper``
(dynamics_proc/control/controller.py), written out here so the FMU is self-contained.

Once per sensor frame it gets each section's measured peak height (NaN: no valid cells or no measurement),
the spout position, the predicted drift and impact points (cart grid frame, m) and the nudge signal; it keeps
the last valid height per section, latches sections full at full_fraction * target_m, gives up a section that
stays unmeasured for stale_timeout_s, fills the first not-full section from the front, and nudges the Machine
Sync setpoint (-1/0/+1 steps of nudge_m, at most one per nudge_interval_s) towards the section's centre less
the drift plus a slowly learnt bias; the auger runs while the target is near and both impact points are safely
inside the cart. Sections: up to MAX_SECTIONS, set by the parameter ``sections``.
"""
import math

from pythonfmu import Boolean, Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real

MAX_SECTIONS = 9
PARAMETERS = {
    "target_m": 1.9, "full_fraction": 0.995, "length_m": 6.0, "width_m": 3.0, "safe_margin_m": 0.3,
    "safety_hysteresis_m": 0.1, "nudge_m": 0.3, "nudge_interval_s": 1.0, "stale_timeout_s": 10.0,
    "frame_dt_s": 0.1, "bias_tau_s": 5.0, "settle_s": 6.0, "travel_on_sections": 1.5,
}
INPUTS = ("spout_x", "drift_x", "nudge_signal", "top_x", "top_y", "floor_x", "floor_y")
#: slack on the nudge threshold (half a nudge), m
NUDGE_SLACK_M = 1e-9


class SectionFill(Fmi2Slave):
    author = "graincosim example"
    description = "Section-fill offloading controller (front to back) with Machine Sync nudges"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        for k in range(1, MAX_SECTIONS + 1):
            setattr(self, f"height_{k}", math.nan)
            self.register_variable(Real(f"height_{k}", causality=Fmi2Causality.input))
        for name in INPUTS:
            setattr(self, name, 0.0)
            self.register_variable(Real(name, causality=Fmi2Causality.input))
        self.nudge, self.target, self.auger_on, self.all_full = 0, 0, False, False
        self.desired_x, self.effort = 0.0, 0.0
        self.register_variable(Integer("nudge", causality=Fmi2Causality.output))
        self.register_variable(Boolean("auger_on", causality=Fmi2Causality.output))
        self.register_variable(Real("desired_x", causality=Fmi2Causality.output))
        self.register_variable(Real("effort", causality=Fmi2Causality.output))
        self.register_variable(Integer("target", causality=Fmi2Causality.output))
        self.register_variable(Boolean("all_full", causality=Fmi2Causality.output))
        self.bias_out = 0.0
        self.register_variable(Real("bias_out", causality=Fmi2Causality.output))
        for k in range(1, MAX_SECTIONS + 1):
            setattr(self, f"fullness_{k}", math.nan)
            self.register_variable(Real(f"fullness_{k}", causality=Fmi2Causality.output))
        for name, value in PARAMETERS.items():
            setattr(self, name, value)
            self.register_variable(Real(name, causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed))
        self.sections = MAX_SECTIONS
        self.register_variable(Integer("sections", causality=Fmi2Causality.parameter,
                                       variability=Fmi2Variability.fixed))

    def exit_initialization_mode(self):
        n = self.sections
        if not 1 <= n <= MAX_SECTIONS:
            raise ValueError(f"sections must be 1..{MAX_SECTIONS}, got {n}")
        self.heights = [math.nan] * n
        self.last_valid = [-math.inf] * n
        self.forced = [False] * n
        self.full = [False] * n
        self.current, self.last_nudge_t, self.bias, self.auger, self.seen = -1, -math.inf, 0.0, False, False

    def inside(self, x, y, margin):
        return margin <= x <= self.length_m - margin and margin <= y <= self.width_m - margin

    def do_step(self, t, step_size):
        n = self.sections
        sl = self.length_m / n
        for i in range(n):
            h = getattr(self, f"height_{i + 1}")
            if not math.isnan(h):
                self.heights[i], self.last_valid[i], self.seen = h, t, True
        cur = self.current
        if (self.seen and cur >= 0 and self.auger and t - self.last_valid[cur] > self.stale_timeout_s
                and not self.forced[cur]):
            self.forced[cur] = True
        level = self.full_fraction * self.target_m
        self.full = [self.full[i] or self.forced[i] or self.heights[i] >= level for i in range(n)]
        if self.seen:                                   # front to back: keep the current section until full
            if not (0 <= cur < n and not self.full[cur]):
                cur = next((i for i in range(n) if not self.full[i]), -1)
        else:
            cur = -1
        self.current = cur
        x, drift, signal = self.spout_x, self.drift_x, self.nudge_signal
        lo, hi = self.safe_margin_m, self.length_m - self.safe_margin_m
        desired = min(max((cur + 0.5) * sl - drift, lo - drift), hi - drift) if cur >= 0 else x
        if t - self.last_nudge_t >= self.settle_s:
            self.bias += (self.frame_dt_s / self.bias_tau_s) * ((signal - x) - self.bias)
        effort = desired + self.bias
        nudge, err = 0, effort - signal
        if cur >= 0 and t - self.last_nudge_t >= self.nudge_interval_s and abs(err) >= 0.5 * self.nudge_m - NUDGE_SLACK_M:
            step = 1 if err > 0 else -1
            if lo <= signal + step * self.nudge_m - self.bias + drift <= hi:
                nudge, self.last_nudge_t = step, t
        margin = max(self.safe_margin_m - self.safety_hysteresis_m, 0.0) if self.auger else self.safe_margin_m
        safe = self.inside(self.top_x, self.top_y, margin) and self.inside(self.floor_x, self.floor_y, margin)
        near = cur >= 0 and abs(x + drift - (cur + 0.5) * sl) <= self.travel_on_sections * self.length_m / n
        self.auger = bool(self.seen and cur >= 0 and safe and near)
        self.nudge, self.auger_on, self.desired_x, self.effort = nudge, self.auger, desired, effort
        self.target, self.all_full, self.bias_out = cur + 1, self.seen and cur < 0, self.bias
        for i in range(n):
            setattr(self, f"fullness_{i + 1}", self.heights[i] / self.target_m)
        return True
