"""FMUs in the loop (FMI 2.0 and 3.0 co-simulation through fmpy; docs/fmu.md).

* :mod:`.describe`: what an FMU file is (version, kind, model, variables), read without running it;
* :mod:`.roles`: the roles an FMU can play (vehicle, controller, strategy), their signals, the mapping check;
* :mod:`.check`: the scenario-time checks and inventory (run by the loader through cosim.scenario.trust);
* :mod:`.slave`: one instance stepped in lockstep (:class:`FmuSlave`), faults as :class:`FmuStepError`.

fmpy is imported only when an FMU is described or instantiated; importing this package needs nothing extra.
"""
from .describe import FMI_VERSIONS, FmiUnavailable, FmuDescription, FmuInvalid, Variable, describe, require_fmpy
from .roles import CONTROLLER, ROLES, STRATEGY, VEHICLE, Role, Signal, mapping_problems
from .slave import FmuSlave, FmuStepError

__all__ = ["FMI_VERSIONS", "FmiUnavailable", "FmuDescription", "FmuInvalid", "Variable", "describe", "require_fmpy",
           "CONTROLLER", "ROLES", "STRATEGY", "VEHICLE", "Role", "Signal", "mapping_problems", "FmuSlave",
           "FmuStepError"]
