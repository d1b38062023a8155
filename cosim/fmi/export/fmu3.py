"""graincosim's grain fill model, scene, sensors and perception of one scenario as an FMI 3.0 co-simulation FMU.

This file is the FMU's model class (pythonfmu3); ``launch.py export-fmu --fmi 3`` copies it into the FMU, named
after the FMU, beside the scenario it carries. It is a thin shell: the world is
:class:`cosim.fmi.export.world.WorldHost`, so the host needs a Python with graincosim installed (docs/fmu.md).
Per-section outputs are arrays of N elements (section 1 first).
"""
from pythonfmu3 import (
    Boolean,
    DefaultExperiment,
    Dimension,
    Float64,
    Fmi3Causality,
    Fmi3Slave,
    Fmi3Status,
    Fmi3StepResult,
    Fmi3Variability,
    Int32,
)

from cosim.fmi.export.world import StepRefused, WorldHost, inputs, outputs
from cosim.fmi.pythonfmu_exit import binaries_of, release_at_exit

_TYPES = {"Real": Float64, "Integer": Int32, "Boolean": Boolean}
#: every variable changes only at communication points (one per sensor frame)
DISCRETE = Fmi3Variability.discrete


class GrainWorld(Fmi3Slave):
    author = "graincosim"
    description = "Grain fill, scene, sensors and perception (graincosim export-fmu); one doStep per sensor frame"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        for binary in binaries_of(self.resources, type(self).__name__):   # the wrapper's exit order
            release_at_exit(binary)
        self.host = WorldHost(self.resources)
        host = self.host
        self.default_experiment = DefaultExperiment(0.0, host.scenario.duration_s, host.period_s)
        self.time = 0.0
        self.register_variable(Float64("time", causality=Fmi3Causality.independent,
                                       variability=Fmi3Variability.continuous))
        for v in inputs(host.scenario):
            self.register_variable(_TYPES[v.kind](
                v.name, causality=Fmi3Causality.input, variability=DISCRETE, start=v.start, description=v.doc,
                getter=lambda n=v.name: host.inputs[n], setter=lambda x, n=v.name: host.inputs.__setitem__(n, x)))
        for v in outputs(host.scenario):
            dims = [Dimension(start=str(v.size))] if v.size > 1 else []
            self.register_variable(_TYPES[v.kind](v.name, causality=Fmi3Causality.output, variability=DISCRETE,
                                                  description=v.doc, dimensions=dims,
                                                  getter=lambda n=v.name: host.outputs[n]))

    def exit_initialization_mode(self):
        self.host.start()

    def do_step(self, current_time, step_size):
        try:
            self.host.step(current_time, step_size)
        except StepRefused as e:
            self.log(str(e), Fmi3Status.error)
            return Fmi3StepResult(status=Fmi3Status.error)
        self.time = current_time + step_size
        return Fmi3StepResult()

    def terminate(self):
        self.host.close()
