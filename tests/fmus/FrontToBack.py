"""Test FMU: the front_to_back fill strategy (dynamics_proc.control.strategies) as an FMI 2.0 co-simulation FMU.

Inputs full_1..full_9 (Boolean), current (Integer, 1..N, 0 none); output section (Integer, 1..N, 0 all full).
Parameter ``sections`` (<= 9); ``bad_section`` > 0 makes it answer that section instead (a fault to report).
"""
from pythonfmu import Boolean, Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer

MAX_SECTIONS = 9


class FrontToBack(Fmi2Slave):
    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        for k in range(1, MAX_SECTIONS + 1):
            setattr(self, f"full_{k}", False)
            self.register_variable(Boolean(f"full_{k}", causality=Fmi2Causality.input))
        self.current, self.section, self.sections, self.bad_section = 0, 0, MAX_SECTIONS, 0
        self.register_variable(Integer("current", causality=Fmi2Causality.input))
        self.register_variable(Integer("section", causality=Fmi2Causality.output))
        self.register_variable(Integer("sections", causality=Fmi2Causality.parameter,
                                       variability=Fmi2Variability.fixed))
        self.register_variable(Integer("bad_section", causality=Fmi2Causality.parameter,
                                       variability=Fmi2Variability.fixed))

    def do_step(self, t, step_size):
        full = [getattr(self, f"full_{k}") for k in range(1, self.sections + 1)]
        cur = self.current
        if 1 <= cur <= self.sections and not full[cur - 1]:
            self.section = cur
        else:
            self.section = next((k + 1 for k, f in enumerate(full) if not f), 0)
        if self.bad_section:
            self.section = self.bad_section
        return True
