"""The tractor towing a grain cart of TractorCart.py as an FMI 3.0 co-simulation FMU, written with pythonfmu3:
the same equations (tractor_cart_model.py), the same variable names, Float64 and Int32 variables.

Inputs: v_cmd (m/s), delta_cmd (rad). Outputs: x, y (rear-axle centre, world, m), yaw (rad), v (m/s),
delta (rad), cart_yaw (rad). Start values (parameters): x0, y0, yaw0, v0, delta0, cart_yaw0.
"""
from pythonfmu3 import Float64, Fmi3Causality, Fmi3Slave, Fmi3Variability, Int32
from tractor_cart_model import PARAMETERS, STATES, rk4


class TractorCart3(Fmi3Slave):
    author = "graincosim example"
    description = "Kinematic tractor with drivetrain and steering lags towing a single-axle cart (RK4), FMI 3.0"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.time = 0.0
        self.register_variable(Float64("time", causality=Fmi3Causality.independent,
                                       variability=Fmi3Variability.continuous))
        self.v_cmd = 0.0
        self.delta_cmd = 0.0
        self.register_variable(Float64("v_cmd", causality=Fmi3Causality.input))
        self.register_variable(Float64("delta_cmd", causality=Fmi3Causality.input))
        for name in STATES:
            setattr(self, name, 0.0)
            self.register_variable(Float64(name, causality=Fmi3Causality.output))
        for name in STATES:
            setattr(self, name + "0", 0.0)
            self.register_variable(Float64(name + "0", causality=Fmi3Causality.parameter,
                                           variability=Fmi3Variability.fixed))
        for name, value in PARAMETERS.items():
            setattr(self, name, value)
            self.register_variable(Float64(name, causality=Fmi3Causality.parameter,
                                           variability=Fmi3Variability.fixed))
        self.substeps = 1
        self.register_variable(Int32("substeps", causality=Fmi3Causality.parameter,
                                     variability=Fmi3Variability.fixed))

    def exit_initialization_mode(self):
        for name in STATES:
            setattr(self, name, getattr(self, name + "0"))

    def do_step(self, current_time, step_size):
        p = {name: getattr(self, name) for name in PARAMETERS}
        s = rk4([getattr(self, n) for n in STATES], self.v_cmd, self.delta_cmd, p, step_size, self.substeps)
        for n, value in zip(STATES, s):
            setattr(self, n, value)
        self.time = current_time + step_size
        return True
