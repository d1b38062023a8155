"""The roles an FMU can play and the signals of each (our names, units, frames), and the mapping check.

Each role lists our signals: inputs we set before each ``doStep``, outputs we read after it, and initial
values we set before initialisation. A scenario maps each of our names to an FMU variable
(``cosim.scenario.config.Fmu``); :func:`mapping_problems` checks that mapping against the FMU's description:
our name known, required ones present, FMU variable present, causality, type and shape right, parameters
settable with a value of their type within their declared range, step mode allowed, an input clock the role
takes.

Per-section signals (``per_section``) map to one FMU variable per section: the FMU name holds ``{k}``,
replaced by the section number 1..N (``full_{k}`` -> ``full_1`` ... ``full_9``; ``full[{k}]`` for Simulink's
vector naming), or 0..N-1 with the record's ``index_base: 0``; or, in an FMI 3.0 FMU, to one array variable of
N elements (the name without ``{k}``).

An FMI 3.0 FMU may declare one input clock: the run's sensor frame ticks it (:func:`clock_problems` says which
clocks a role takes).
"""
from __future__ import annotations

import difflib
import math
from dataclasses import dataclass

from cosim.scenario.config import Fmu

from .describe import KIND_NAMES, FmuDescription, Variable

__all__ = ["Signal", "Role", "VEHICLE", "STRATEGY", "CONTROLLER", "ROLES", "expand", "step_mode", "mapping_problems",
           "clock_problems", "frame_clock"]

#: FMU variable types that carry a number we can set or read
NUMERIC = ("Real", "Integer", "Boolean", "Enumeration")
#: causalities we may set before initialisation (``initial``)
SETTABLE_AT_START = ("parameter", "input")
#: relative tolerance of a constant clock's interval against the sensor period
CLOCK_INTERVAL_RTOL = 1e-9


@dataclass(frozen=True)
class Signal:
    """One of our signals: ``name`` (units in it), FMU types it may map to, whether a mapping must give it,
    whether it is one variable per section (``{k}`` in the FMU name), whether NaN is a valid value (an output
    that is NaN otherwise ends the run)."""

    name: str
    types: tuple[str, ...]
    required: bool = True
    per_section: bool = False
    doc: str = ""
    nan_ok: bool = False


@dataclass(frozen=True)
class Role:
    """What an FMU stands in for: its signals, the step modes it allows (the first is the default) and the
    ``intervalVariability`` of the FMI 3.0 input clock it may declare (empty: none)."""

    name: str
    label: str
    inputs: tuple[Signal, ...]
    outputs: tuple[Signal, ...]
    initial: tuple[Signal, ...]
    steps: tuple[str, ...]
    clocks: tuple[str, ...] = ()

    def signals(self, kind: str) -> tuple[Signal, ...]:
        """The role's ``inputs``, ``outputs`` or ``initial`` signals."""
        return getattr(self, kind)


_VEHICLE_STATE = (
    Signal("tractor_axle_x_m", ("Real",), doc="tractor rear-axle centre x, world, m"),
    Signal("tractor_axle_y_m", ("Real",), doc="tractor rear-axle centre y, world, m"),
    Signal("tractor_yaw_rad", ("Real",), doc="tractor heading, world, rad (0 along world x, left positive)"),
    Signal("tractor_speed_mps", ("Real",), doc="tractor speed along its heading, m/s"),
    Signal("tractor_steer_rad", ("Real",), doc="front steering angle, rad (left positive)"),
    Signal("cart_yaw_rad", ("Real",), doc="cart heading, world, rad"),
)

#: the tractor and its cart, driven by Machine Sync (dynamics_proc.vehicles.motion, dynamics_proc.vehicles.machine_sync)
VEHICLE = Role(
    "tractor_cart", "vehicles.tractor_cart",
    inputs=(Signal("speed_cmd_mps", ("Real",), doc="Machine Sync's speed command, m/s (>= 0)"),
            Signal("steer_cmd_rad", ("Real",), doc="Machine Sync's steering command, rad (left positive)")),
    outputs=_VEHICLE_STATE,
    initial=tuple(Signal(s.name, ("Real",), required=False, doc=s.doc) for s in _VEHICLE_STATE),
    steps=("dynamics_step", "frame"),
)

#: the fill strategy (dynamics_proc.control.strategies): which section to fill next, sections numbered 1..N
STRATEGY = Role(
    "strategy", "controller (strategy)",
    inputs=(Signal("full", ("Boolean", "Integer", "Real"), per_section=True,
                   doc="section k declared full (latched), 1 / true when full"),
            Signal("height_m", ("Real",), required=False, per_section=True,
                   doc="estimated peak height of section k above the cart floor, m; NaN unknown"),
            Signal("current_section", ("Integer", "Real"), required=False,
                   doc="section being filled, 1..N; 0 none yet")),
    outputs=(Signal("section", ("Integer", "Real", "Enumeration"),
                    doc="section to fill, 1..N; 0 when every section is full"),),
    initial=(),
    steps=("frame",),
    clocks=("triggered",),
)

#: the whole offloading controller (dynamics_proc.control.protocol), positions along the cart grid x axis (m from
#: the front inner wall), sections numbered 1..N
CONTROLLER = Role(
    "controller", "controller (model)",
    inputs=(Signal("height_m", ("Real",), per_section=True,
                   doc="robust peak height of section k in this frame's measurement, m; NaN: no valid cells or "
                       "no measurement"),
            Signal("spout_x_m", ("Real",), required=False, doc="actual auger (spout) location, grid x, m"),
            Signal("drift_x_m", ("Real",), required=False, doc="predicted impact x minus spout x, m"),
            Signal("nudge_signal_m", ("Real",), required=False,
                   doc="spout grid x the current Machine Sync setpoint implies, m"),
            Signal("impact_top_x_m", ("Real",), required=False, doc="predicted impact at the target fill, grid x, m"),
            Signal("impact_top_y_m", ("Real",), required=False, doc="predicted impact at the target fill, grid y, m"),
            Signal("impact_floor_x_m", ("Real",), required=False, doc="predicted impact on the floor, grid x, m"),
            Signal("impact_floor_y_m", ("Real",), required=False, doc="predicted impact on the floor, grid y, m"),
            Signal("delivered_m3", ("Real",), required=False, doc="flow signal integrated since the start, m^3")),
    outputs=(Signal("nudge", ("Integer", "Real", "Enumeration"),
                    doc="-1, 0 or +1: move the Machine Sync setpoint by that many nudge_m along grid x"),
             Signal("auger_on", ("Boolean", "Integer", "Real"), doc="run the auger (non-zero: on)"),
             Signal("desired_x_m", ("Real",), required=False, doc="desired auger location, grid x, m (reported)"),
             Signal("effort_m", ("Real",), required=False, nan_ok=True,
                    doc="control effort, grid x, m (reported; NaN: none)"),
             Signal("target_section", ("Integer", "Real", "Enumeration"), required=False,
                    doc="section being filled 1..N, 0 none (reported)"),
             Signal("all_full", ("Boolean", "Integer", "Real"), required=False,
                    doc="the controller considers the cart full (reported)"),
             Signal("bias_m", ("Real",), required=False, doc="learnt steady-state offset, m (reported)"),
             Signal("fullness", ("Real",), required=False, per_section=True, nan_ok=True,
                    doc="estimated height / target fill of section k, NaN unknown (reported)")),
    initial=(),
    steps=("frame",),
    clocks=("triggered", "constant"),
)

ROLES = {r.name: r for r in (VEHICLE, STRATEGY, CONTROLLER)}


def expand(signal: Signal, fmu_name: str, sections: int, base: int = 1) -> list[str]:
    """The FMU variable names a mapping entry stands for: one per section for a per-section signal whose name holds
    ``{k}`` (k = base .. base + N - 1); else the name itself (a scalar, or for a per-section signal an FMI 3.0 array
    of N elements)."""
    if signal.per_section and "{k}" in fmu_name:
        return [fmu_name.replace("{k}", str(k)) for k in range(base, base + sections)]
    return [fmu_name]


def step_mode(fmu: Fmu, role: Role) -> str:
    """The step mode the FMU runs with: the record's, else the role's default."""
    return fmu.step or role.steps[0]


def frame_clock(desc: FmuDescription) -> Variable | None:
    """The FMU's input clock the sensor frame ticks (its only one), or None."""
    clocks = desc.input_clocks()
    return clocks[0] if len(clocks) == 1 else None


def _unknown(name: str, known, what: str, where: str = "") -> str:
    close = difflib.get_close_matches(name, list(known), n=1)
    hint = f" (did you mean {close[0]!r}?)" if close else ""
    return f"no {what} {name!r}{where}{hint}"


def _kinds(desc: FmuDescription, kinds: tuple[str, ...]) -> str:
    names = KIND_NAMES[desc.fmi_version]
    return " or ".join(names[k] for k in kinds)


def _check_variable(var: Variable | None, fmu_name: str, desc: FmuDescription, causalities: tuple[str, ...],
                    types: tuple[str, ...], size: int | None = None) -> str | None:
    """Why ``var`` cannot be mapped here (None: it can): missing, wrong causality, type or shape. ``size``: the
    array length wanted (None: a scalar)."""
    if var is None:
        return _unknown(fmu_name, desc.variables, "variable", f" in the FMU {desc.path.name}")
    if var.causality not in causalities:
        return (f"FMU variable {fmu_name!r} has causality {var.causality!r}; it must be "
                f"{' or '.join(map(repr, causalities))} here")
    if var.kind is None:
        return (f"FMU variable {fmu_name!r} is {var.type}, a type graincosim does not map; use "
                f"{_kinds(desc, types)}")
    if var.kind not in types:
        return f"FMU variable {fmu_name!r} is {var.type}; it must be {_kinds(desc, types)} here"
    if size is None and var.shape:
        return f"FMU variable {fmu_name!r} is an array of shape {var.shape}; it must be a scalar here"
    if size is not None and var.shape != (size,):
        got = f"an array of shape {var.shape}" if var.shape else "a scalar"
        return (f"FMU variable {fmu_name!r} is {got}; a per-section signal maps to an array of {size} elements "
                "(one per section), or to one scalar per section with {k} in the name")
    return None


def _value_problem(var: Variable, value) -> str | None:
    """Why ``value`` cannot be given to parameter ``var``: not of its type, or outside its declared range."""
    ok = {"Real": isinstance(value, (int, float)) and not isinstance(value, bool),
          "Integer": isinstance(value, int) and not isinstance(value, bool),
          "Enumeration": isinstance(value, int) and not isinstance(value, bool),
          "Boolean": isinstance(value, bool), "String": isinstance(value, str)}.get(var.kind, False)
    if not ok:
        return f"FMU parameter {var.name!r} is {var.type}, got {value!r}"
    if var.kind in ("Real", "Integer", "Enumeration"):
        lo = -math.inf if var.min is None else float(var.min)
        hi = math.inf if var.max is None else float(var.max)
        if not lo <= value <= hi:
            return (f"FMU parameter {var.name!r} must be within [{var.min or '-inf'}, {var.max or 'inf'}] (its range "
                    f"in the FMU's model description), got {value!r}")
    return None


def _per_section_problem(ours: str, theirs: str, desc: FmuDescription, sections: int, base: int) -> str | None:
    """Why a per-section mapping without ``{k}`` cannot be an array here (FMI 2.0 has none), or None."""
    if desc.fmi_version == "2.0":
        return (f"{ours!r} is one value per section: the FMU name must hold {{k}} (the section number "
                f"{base}..{sections - 1 + base}), e.g. '{theirs}_{{k}}'")
    return None


def _element_hint(theirs: str, desc: FmuDescription) -> str:
    """For an FMI 3.0 FMU, a hint when ``name[{k}]`` names the elements of an array variable ``name``."""
    base = theirs.split("[", 1)[0]
    var = desc.variables.get(base)
    if desc.fmi_version != "2.0" and "[{k}]" in theirs and var is not None and var.shape:
        return f"; FMI 3.0 arrays have no element names: map the whole array, {base!r}"
    return ""


def mapping_problems(fmu: Fmu, desc: FmuDescription, role: Role, sections: int,
                     frame_s: float | None = None) -> list[tuple[tuple, str]]:
    """Every problem of ``fmu``'s mapping for ``role`` against ``desc``, as (location inside the record,
    message). ``sections``: the controller's section count N; ``frame_s``: the sensor period, s (the clock check;
    None leaves it out)."""
    out: list[tuple[tuple, str]] = []
    causality = {"inputs": ("input",), "outputs": ("output",), "initial": SETTABLE_AT_START}
    for kind in ("inputs", "outputs", "initial"):
        signals = {s.name: s for s in role.signals(kind)}
        mapping = getattr(fmu, kind)
        for ours, theirs in mapping.items():
            sig = signals.get(ours)
            if sig is None:
                known = ", ".join(signals) or "none"
                what = {"inputs": "input", "outputs": "output", "initial": "initial value"}[kind]
                out.append(((kind, ours), _unknown(ours, signals, f"{what} signal") +
                            f" for the {role.label} FMU; known: {known}"))
                continue
            array = sig.per_section and "{k}" not in theirs
            if array and (msg := _per_section_problem(ours, theirs, desc, sections, fmu.index_base)):
                out.append(((kind, ours), msg))
                continue
            for name in expand(sig, theirs, sections, fmu.index_base):
                msg = _check_variable(desc.variables.get(name), name, desc, causality[kind], sig.types,
                                      sections if array else None)
                if msg:
                    out.append(((kind, ours), msg + _element_hint(theirs, desc)))
                    break
        missing = [s.name for s in role.signals(kind) if s.required and s.name not in mapping]
        if missing:
            out.append(((kind,) if mapping else (), f"the {role.label} FMU needs {kind} "
                        f"{', '.join(map(repr, missing))} mapped (our name: FMU variable name)"))
    for name, value in fmu.parameters.items():
        var = desc.variables.get(name)
        msg = _check_variable(var, name, desc, ("parameter",), NUMERIC + ("String",))
        if msg:
            out.append((("parameters", name), msg))
        elif (msg := _value_problem(var, value)) is not None:
            out.append((("parameters", name), msg))
    if fmu.step is not None and fmu.step not in role.steps:
        out.append((("step",), f"the {role.label} FMU can only be stepped per {' or '.join(role.steps)}"))
    if frame_s is not None:
        out += [(("path",), msg) for msg in clock_problems(desc, role, frame_s)]
    return out


def clock_problems(desc: FmuDescription, role: Role, frame_s: float) -> list[str]:
    """Why the FMU's input clocks do not fit ``role`` with a sensor period of ``frame_s`` s (empty: they do). The
    sensor frame ticks one input clock: ``triggered`` (ticked at each decision) or, for the controller, ``constant``
    with an interval of one sensor period from t = 0."""
    clocks = desc.input_clocks()
    if not clocks:
        return []
    names = ", ".join(repr(c.name) for c in clocks)
    if len(clocks) > 1:
        return [f"{desc.path.name} declares {len(clocks)} input clocks ({names}); graincosim ticks one, the "
                "sensor frame"]
    c = clocks[0]
    kind = c.clock.interval_variability if c.clock else ""
    if not role.clocks:
        return [f"{desc.path.name} declares the input clock {c.name!r}; the {role.label} FMU is stepped per "
                "dynamics step or frame and takes no clock"]
    if kind not in role.clocks:
        return [f"{desc.path.name}: input clock {c.name!r} has intervalVariability {kind!r}; the {role.label} FMU's "
                f"clock must be {' or '.join(map(repr, role.clocks))} (the sensor frame ticks it)"]
    problems = []
    if kind == "constant":
        interval, shift = c.clock.interval_s, c.clock.shift_s or 0.0
        if interval is None or abs(interval - frame_s) > CLOCK_INTERVAL_RTOL * frame_s or shift != 0.0:
            problems.append(f"{desc.path.name}: input clock {c.name!r} ticks every {interval} s from {shift} s; the "
                            f"sensor frame ticks every timing.sensor_period_s = {frame_s} s from 0 s")
    if not desc.has_event_mode:
        problems.append(f"{desc.path.name} declares the input clock {c.name!r} but not hasEventMode=\"true\" "
                        "(a clock ticks in Event Mode)")
    return problems
