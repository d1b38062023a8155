"""The equations of the example tractor-cart FMUs (TractorCart.py: FMI 2.0, TractorCart3.py: FMI 3.0) and their
variables and step (:func:`register`, :func:`start`, :func:`advance`), shared so that both wrap one model and
differ only by the FMI version's types. The same equations as graincosim's built-in model (dynamics_proc/vehicles/motion.py), written
out here so the FMUs are self-contained: a kinematic bicycle about the rear axle with a first-order drivetrain lag
(acceleration and braking limits) and a first-order steering lag (rate limit), towing a single-axle cart from a
hitch behind the rear axle. Integrated with classic RK4 (Simulink's ode4), inputs held over a step.

State (x, y, yaw, v, delta, cart_yaw): rear-axle centre (world, m), heading (rad), speed (m/s), front steering
angle (rad), cart heading (rad). Inputs v_cmd (m/s), delta_cmd (rad).
"""
import math

#: parameter name -> default value (SI units, as their names say)
PARAMETERS = {
    "wheelbase_m": 3.0, "hitch_offset_m": 1.5, "tow_length_m": 8.08, "drivetrain_tau_s": 0.5,
    "accel_max_mps2": 1.0, "brake_max_mps2": 3.0, "steer_tau_s": 0.2, "steer_rate_max_radps": math.radians(30.0),
}
STATES = ("x", "y", "yaw", "v", "delta", "cart_yaw")


def clip(a, lo, hi):
    return lo if a < lo else hi if a > hi else a


def derivative(s, v_cmd, delta_cmd, p):
    """d/dt of the state ``s`` (6 floats) with the inputs held; ``p``: parameter name -> value."""
    x, y, yaw, v, delta, pyaw = s
    r = v * math.tan(delta) / p["wheelbase_m"]
    rel = yaw - pyaw
    dp = (v * math.sin(rel) - p["hitch_offset_m"] * r * math.cos(rel)) / p["tow_length_m"]
    dv = clip((v_cmd - v) / p["drivetrain_tau_s"], -p["brake_max_mps2"], p["accel_max_mps2"])
    dd = clip((delta_cmd - delta) / p["steer_tau_s"], -p["steer_rate_max_radps"], p["steer_rate_max_radps"])
    return [v * math.cos(yaw), v * math.sin(yaw), r, dv, dd, dp]


def rk4(s, v_cmd, delta_cmd, p, step_s, substeps):
    """The state after ``step_s`` seconds: ``substeps`` classic RK4 steps from ``s``, inputs held."""
    h = step_s / substeps
    for _ in range(substeps):
        k1 = derivative(s, v_cmd, delta_cmd, p)
        k2 = derivative([a + 0.5 * h * b for a, b in zip(s, k1)], v_cmd, delta_cmd, p)
        k3 = derivative([a + 0.5 * h * b for a, b in zip(s, k2)], v_cmd, delta_cmd, p)
        k4 = derivative([a + h * b for a, b in zip(s, k3)], v_cmd, delta_cmd, p)
        s = [a + (h / 6.0) * (b1 + 2.0 * b2 + 2.0 * b3 + b4) for a, b1, b2, b3, b4 in zip(s, k1, k2, k3, k4)]
    return s


def register(slave, real, integer, causality, variability):
    """Declare the FMU's variables on ``slave``, the same for either FMI version: ``real`` and ``integer`` are the
    version's variable types, ``causality`` and ``variability`` its enums (FMI 2.0 with pythonfmu: ``Real``,
    ``Integer``, ``Fmi2Causality``, ``Fmi2Variability``; FMI 3.0 with pythonfmu3: ``Float64``, ``Int32``,
    ``Fmi3Causality``, ``Fmi3Variability``)."""
    slave.v_cmd = 0.0
    slave.delta_cmd = 0.0
    slave.register_variable(real("v_cmd", causality=causality.input))
    slave.register_variable(real("delta_cmd", causality=causality.input))
    for name in STATES:
        setattr(slave, name, 0.0)
        slave.register_variable(real(name, causality=causality.output))
    for name in STATES:
        setattr(slave, name + "0", 0.0)
        slave.register_variable(real(name + "0", causality=causality.parameter, variability=variability.fixed))
    for name, value in PARAMETERS.items():
        setattr(slave, name, value)
        slave.register_variable(real(name, causality=causality.parameter, variability=variability.fixed))
    slave.substeps = 1
    slave.register_variable(integer("substeps", causality=causality.parameter, variability=variability.fixed))


def start(slave):
    """The state at the start values (the ``<state>0`` parameters), when the FMU leaves initialisation."""
    for name in STATES:
        setattr(slave, name, getattr(slave, name + "0"))


def advance(slave, step_size):
    """One ``doStep`` of ``step_size`` s: :func:`rk4` with the slave's parameters and held inputs."""
    p = {name: getattr(slave, name) for name in PARAMETERS}
    s = rk4([getattr(slave, n) for n in STATES], slave.v_cmd, slave.delta_cmd, p, step_size, slave.substeps)
    for n, value in zip(STATES, s):
        setattr(slave, n, value)
