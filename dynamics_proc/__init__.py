"""The system model (the paper's Simulink side): vehicles, Machine Sync, auger and stream, grain fill,
offloading controller; it owns the ground truth.

Subpackages by the paper's blocks: ``vehicles`` (vehicle models, integration, Machine Sync, ground, field
conditions), ``grain`` (auger and stream, grain fill, tilt), ``control`` (the offloading controller and its
contract), ``fmu`` (FMUs in place of built-in models, the dynamics driven from outside). At the top: ``model``
(one frame, pure), ``state`` (its value types), ``record`` (the ``dyn_state`` fields), ``closed_loop``, and the
thin ring participant (``participant``, ``blocks``, ``summary``). docs/paper.md maps each block of the paper to
its function and its test. Importing the package imports nothing else.
"""
