"""The system model (the paper's Simulink side): vehicles, Machine Sync, auger and stream, grain fill,
offloading controller; it owns the ground truth. Pure modules (vehicles, integrators, machine_sync, auger,
grainfill, strategies, controller, model, closed_loop, summary) and the thin ring participant (participant,
blocks). Importing the package imports nothing else.
"""
