"""A tractor towing a grain cart as an FMU (FMI 2.0 co-simulation), written with pythonfmu: the equations of
tractor_cart_model.py (the built-in model's), RK4 with ``substeps`` steps per ``doStep``, inputs held.

Inputs: v_cmd (m/s), delta_cmd (rad). Outputs: x, y (rear-axle centre, world, m), yaw (rad), v (m/s),
delta (rad), cart_yaw (rad). Start values (parameters): x0, y0, yaw0, v0, delta0, cart_yaw0.
"""
from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real
from tractor_cart_model import PARAMETERS, STATES, rk4


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

    def do_step(self, current_time, step_size):
        p = {name: getattr(self, name) for name in PARAMETERS}
        s = rk4([getattr(self, n) for n in STATES], self.v_cmd, self.delta_cmd, p, step_size, self.substeps)
        for n, value in zip(STATES, s):
            setattr(self, n, value)
        return True
