"""A tractor towing a grain cart as an FMU (FMI 2.0 co-simulation), written with pythonfmu.

The same equations as graincosim's built-in model (dynamics_proc/vehicles.py), written out here so the FMU is
self-contained: a kinematic bicycle about the rear axle with a first-order drivetrain lag (acceleration and
braking limits) and a first-order steering lag (rate limit), towing a single-axle cart from a hitch behind the
rear axle. Integrated with classic RK4 (Simulink's ode4), ``substeps`` steps per ``doStep``, inputs held.

Inputs: v_cmd (m/s), delta_cmd (rad). Outputs: x, y (rear-axle centre, world, m), yaw (rad), v (m/s),
delta (rad), cart_yaw (rad). Start values (parameters): x0, y0, yaw0, v0, delta0, cart_yaw0.
"""
import math

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real

PARAMETERS = {
    "wheelbase_m": 3.0, "hitch_offset_m": 1.5, "tow_length_m": 8.08, "drivetrain_tau_s": 0.5,
    "accel_max_mps2": 1.0, "brake_max_mps2": 3.0, "steer_tau_s": 0.2, "steer_rate_max_radps": math.radians(30.0),
}
STATES = ("x", "y", "yaw", "v", "delta", "cart_yaw")


def clip(a, lo, hi):
    return lo if a < lo else hi if a > hi else a


class TractorCart(Fmi2Slave):
    author = "graincosim example"
    description = "Kinematic tractor with drivetrain and steering lags towing a single-axle cart (RK4)"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.v_cmd = 0.0
        self.delta_cmd = 0.0
        self.register_variable(Real("v_cmd", causality=Fmi2Causality.input))
        self.register_variable(Real("delta_cmd", causality=Fmi2Causality.input))
        for name in STATES:
            setattr(self, name, 0.0)
            self.register_variable(Real(name, causality=Fmi2Causality.output))
        for name in STATES:
            setattr(self, name + "0", 0.0)
            self.register_variable(Real(name + "0", causality=Fmi2Causality.parameter,
                                        variability=Fmi2Variability.fixed))
        for name, value in PARAMETERS.items():
            setattr(self, name, value)
            self.register_variable(Real(name, causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed))
        self.substeps = 1
        self.register_variable(Integer("substeps", causality=Fmi2Causality.parameter,
                                       variability=Fmi2Variability.fixed))

    def exit_initialization_mode(self):
        for name in STATES:
            setattr(self, name, getattr(self, name + "0"))

    def derivative(self, s):
        """d/dt of (x, y, yaw, v, delta, cart_yaw) with the inputs held."""
        x, y, yaw, v, delta, pyaw = s
        r = v * math.tan(delta) / self.wheelbase_m
        rel = yaw - pyaw
        dp = (v * math.sin(rel) - self.hitch_offset_m * r * math.cos(rel)) / self.tow_length_m
        dv = clip((self.v_cmd - v) / self.drivetrain_tau_s, -self.brake_max_mps2, self.accel_max_mps2)
        dd = clip((self.delta_cmd - delta) / self.steer_tau_s, -self.steer_rate_max_radps, self.steer_rate_max_radps)
        return [v * math.cos(yaw), v * math.sin(yaw), r, dv, dd, dp]

    def do_step(self, current_time, step_size):
        h = step_size / self.substeps
        s = [getattr(self, n) for n in STATES]
        for _ in range(self.substeps):
            k1 = self.derivative(s)
            k2 = self.derivative([a + 0.5 * h * b for a, b in zip(s, k1)])
            k3 = self.derivative([a + 0.5 * h * b for a, b in zip(s, k2)])
            k4 = self.derivative([a + h * b for a, b in zip(s, k3)])
            s = [a + (h / 6.0) * (b1 + 2.0 * b2 + 2.0 * b3 + b4) for a, b1, b2, b3, b4 in zip(s, k1, k2, k3, k4)]
        for n, value in zip(STATES, s):
            setattr(self, n, value)
        return True
