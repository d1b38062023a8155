"""Test FMU: a tractor-cart stand-in (the vehicle role's variables) that holds its start state and fails on
purpose once t >= fail_at_s: ``mode`` 1 returns an error from doStep, 2 outputs NaN for x."""
import math

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real

STATES = ("x", "y", "yaw", "v", "delta", "cart_yaw")


class Faulty(Fmi2Slave):
    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.v_cmd, self.delta_cmd = 0.0, 0.0
        self.register_variable(Real("v_cmd", causality=Fmi2Causality.input))
        self.register_variable(Real("delta_cmd", causality=Fmi2Causality.input))
        for name in STATES:
            setattr(self, name, 0.0)
            self.register_variable(Real(name, causality=Fmi2Causality.output))
            setattr(self, name + "0", 0.0)
            self.register_variable(Real(name + "0", causality=Fmi2Causality.parameter,
                                        variability=Fmi2Variability.fixed))
        self.fail_at_s, self.mode = 1.0, 1
        self.register_variable(Real("fail_at_s", causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed))
        self.register_variable(Integer("mode", causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed))

    def exit_initialization_mode(self):
        for name in STATES:
            setattr(self, name, getattr(self, name + "0"))

    def do_step(self, t, step_size):
        if t + 0.5 * step_size >= self.fail_at_s:
            if self.mode == 1:
                return False
            self.x = math.nan
        return True
