"""A tractor towing a grain cart as an FMU (FMI 2.0 co-simulation), written with pythonfmu: the equations of
tractor_cart_model.py (the built-in model's), RK4 with ``substeps`` steps per ``doStep``, inputs held. Its
variables and step are tractor_cart_model's, shared with the FMI 3.0 twin TractorCart3.py.

Inputs: v_cmd (m/s), delta_cmd (rad). Outputs: x, y (rear-axle centre, world, m), yaw (rad), v (m/s),
delta (rad), cart_yaw (rad). Start values (parameters): x0, y0, yaw0, v0, delta0, cart_yaw0.
"""
from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real
from tractor_cart_model import advance, register, start


class TractorCart(Fmi2Slave):
    author = "graincosim example"
    description = "Kinematic tractor with drivetrain and steering lags towing a single-axle cart (RK4)"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        register(self, Real, Integer, Fmi2Causality, Fmi2Variability)

    def exit_initialization_mode(self):
        start(self)

    def do_step(self, current_time, step_size):
        advance(self, step_size)
        return True
