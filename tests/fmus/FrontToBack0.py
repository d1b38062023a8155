"""Test FMU: the front_to_back fill strategy (dynamics_proc.control.strategies) as an FMI 2.0 co-simulation FMU that numbers
sections from 0, as a Python strategy does: inputs full_0..full_8 (Boolean), current (Integer, 0..N-1, -1 none);
output section (Integer, 0..N-1, -1 when every section is full). Parameter ``sections`` (<= 9). Mapped with
``index_base: 0``.
"""
from pythonfmu import Boolean, Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer

MAX_SECTIONS = 9


class FrontToBack0(Fmi2Slave):
    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        for k in range(MAX_SECTIONS):
            setattr(self, f"full_{k}", False)
            self.register_variable(Boolean(f"full_{k}", causality=Fmi2Causality.input))
        self.current, self.section, self.sections = -1, -1, MAX_SECTIONS
        self.register_variable(Integer("current", causality=Fmi2Causality.input))
        self.register_variable(Integer("section", causality=Fmi2Causality.output))
        self.register_variable(Integer("sections", causality=Fmi2Causality.parameter,
                                       variability=Fmi2Variability.fixed))

    def do_step(self, t, step_size):
        full = [getattr(self, f"full_{k}") for k in range(self.sections)]
        cur = self.current
        if 0 <= cur < self.sections and not full[cur]:
            self.section = cur
        else:
            self.section = next((k for k, f in enumerate(full) if not f), -1)
        return True
