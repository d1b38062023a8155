"""The tractor towing a grain cart of TractorCart.py as an FMI 3.0 co-simulation FMU, written with pythonfmu3:
the same equations, variables and step (tractor_cart_model.py) with Float64 and Int32 variables, and the
independent variable ``time`` FMI 3.0 asks for.

Inputs: v_cmd (m/s), delta_cmd (rad). Outputs: x, y (rear-axle centre, world, m), yaw (rad), v (m/s),
delta (rad), cart_yaw (rad). Start values (parameters): x0, y0, yaw0, v0, delta0, cart_yaw0.
"""
from pythonfmu3 import Float64, Fmi3Causality, Fmi3Slave, Fmi3Variability, Int32
from tractor_cart_model import advance, register, start


class TractorCart3(Fmi3Slave):
    author = "graincosim example"
    description = "Kinematic tractor with drivetrain and steering lags towing a single-axle cart (RK4), FMI 3.0"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.time = 0.0
        self.register_variable(Float64("time", causality=Fmi3Causality.independent,
                                       variability=Fmi3Variability.continuous))
        register(self, Float64, Int32, Fmi3Causality, Fmi3Variability)

    def exit_initialization_mode(self):
        start(self)

    def do_step(self, current_time, step_size):
        advance(self, step_size)
        self.time = current_time + step_size
        return True
