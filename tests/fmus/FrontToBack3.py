"""Test FMU: the front_to_back fill strategy (dynamics_proc.control.strategies) as an FMI 3.0 co-simulation FMU whose
section vectors are arrays: ``full`` (Boolean[9]) and ``height`` (Float64[9], m) in, ``current`` (Int64, 1..N,
0 none) in, ``section`` (Int32, 1..N, 0 all full) out; ``highest_height`` (Float64) out reports the largest
finite height it was given (so a test can see the array arrive). Parameter ``sections`` (<= 9).

Array variables get explicit setters: pythonfmu3's default one calls numpy.reshape(newshape=...), which numpy 2
removed.
"""
import math

import numpy as np
from pythonfmu3 import Boolean, Dimension, Float64, Fmi3Causality, Fmi3Slave, Fmi3Variability, Int32, Int64

MAX_SECTIONS = 9


class FrontToBack3(Fmi3Slave):
    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.time = 0.0
        self.register_variable(Float64("time", causality=Fmi3Causality.independent,
                                       variability=Fmi3Variability.continuous))
        self.full = np.zeros(MAX_SECTIONS, dtype=bool)
        self.height = np.full(MAX_SECTIONS, math.nan)
        dim = [Dimension(start=str(MAX_SECTIONS))]
        self.register_variable(Boolean("full", causality=Fmi3Causality.input, dimensions=dim,
                                       setter=lambda v: self._put("full", v, bool)))
        self.register_variable(Float64("height", causality=Fmi3Causality.input, dimensions=dim,
                                       setter=lambda v: self._put("height", v, float)))
        self.current, self.section, self.sections, self.highest_height = 0, 0, MAX_SECTIONS, 0.0
        self.register_variable(Int64("current", causality=Fmi3Causality.input))
        self.register_variable(Int32("section", causality=Fmi3Causality.output))
        self.register_variable(Float64("highest_height", causality=Fmi3Causality.output))
        self.register_variable(Int32("sections", causality=Fmi3Causality.parameter,
                                     variability=Fmi3Variability.fixed))

    def _put(self, name, values, dtype):
        setattr(self, name, np.array(values, dtype=dtype))

    def do_step(self, current_time, step_size):
        full = self.full[: self.sections]
        cur = self.current
        if 1 <= cur <= self.sections and not full[cur - 1]:
            self.section = cur
        else:
            self.section = next((k + 1 for k, f in enumerate(full) if not f), 0)
        finite = self.height[np.isfinite(self.height)]
        self.highest_height = float(finite.max()) if finite.size else 0.0
        self.time = current_time + step_size
        return True
