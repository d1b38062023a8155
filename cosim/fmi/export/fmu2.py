"""graincosim's grain fill model, scene, sensors and perception of one scenario as an FMI 2.0 co-simulation FMU.

This file is the FMU's model class (pythonfmu); ``launch.py export-fmu`` copies it into the FMU, named after the
FMU, beside the scenario it carries. It is a thin shell: the world is :class:`cosim.fmi.export.world.WorldHost`,
so the host needs a Python with graincosim installed (docs/fmu.md). Per-section outputs are scalars named
``name[1]`` ... ``name[N]`` (Simulink's vector naming).
"""
from pythonfmu import Boolean, DefaultExperiment, Fmi2Causality, Fmi2Slave, Integer, Real
from pythonfmu.enums import Fmi2Status, Fmi2Variability

from cosim.fmi.export.world import StepRefused, WorldHost, inputs, outputs
from cosim.fmi.pythonfmu_exit import binaries_of, release_at_exit

_TYPES = {"Real": Real, "Integer": Integer, "Boolean": Boolean}
#: every variable changes only at communication points (one per sensor frame)
DISCRETE = Fmi2Variability.discrete


class GrainWorld(Fmi2Slave):
    author = "graincosim"
    description = "Grain fill, scene, sensors and perception (graincosim export-fmu); one doStep per sensor frame"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        for binary in binaries_of(self.resources, type(self).__name__):   # the wrapper's exit order
            release_at_exit(binary)
        self.host = WorldHost(self.resources)
        host = self.host
        self.default_experiment = DefaultExperiment(0.0, host.scenario.duration_s, host.period_s)
        for v in inputs(host.scenario):
            self.register_variable(_TYPES[v.kind](
                v.name, causality=Fmi2Causality.input, variability=Fmi2Variability.discrete, start=v.start,
                description=v.doc,
                getter=lambda n=v.name: host.inputs[n], setter=lambda x, n=v.name: host.inputs.__setitem__(n, x)))
        for v in outputs(host.scenario):
            make = _TYPES[v.kind]
            if v.size == 1:
                self.register_variable(make(v.name, causality=Fmi2Causality.output, variability=DISCRETE,
                                            description=v.doc, getter=lambda n=v.name: host.outputs[n]))
                continue
            for k in range(v.size):
                self.register_variable(make(f"{v.name}[{k + 1}]", causality=Fmi2Causality.output,
                                            variability=DISCRETE, description=f"section {k + 1}: {v.doc}",
                                            getter=lambda n=v.name, k=k: host.outputs[n][k]))

    def exit_initialization_mode(self):
        self.host.start()

    def do_step(self, current_time, step_size):
        try:
            self.host.step(current_time, step_size)
        except StepRefused as e:
            self.log(str(e), Fmi2Status.error)
            return False
        return True

    def terminate(self):
        self.host.close()
