"""The world inside an exported FMU: grain fill, scene, sensors and perception of one scenario, stepped by a
foreign master (docs/fmu.md, "Export").

:class:`WorldHost` runs in the master's process (the FMU's Python, see docs/fmu.md): it loads the scenario the FMU
carries, sets up the ring over the in-process transport (a segment in ordinary memory, nothing spawned) with the
dynamics role played by :class:`dynamics_proc.fmu.external.ExternalDynamicsParticipant` and the scenario's renderer and
perception as in a launched run, and steps it one sensor frame per ``doStep``.

Variables (:func:`inputs` and :func:`outputs`, our names; units in them): the inputs are what a vehicle-and-
controller model produces (:class:`dynamics_proc.fmu.external.WorldInputs`), the outputs what a controller consumes:
perceived per-section peak heights and fullness (the built-in controller's robust section peak of the perceived
height map, NaN where a section has too few valid cells or the cart was not found), the perceived cart pose,
impact point and coverage, and the ground-truth values beside them. Per-section outputs are N values
(``controller.sections``), section 1 first.

Timing: frame 0 (the scene at the start values, t = 0) runs when the FMU leaves initialisation; each
``doStep(t, h)`` must be one frame (h = ``timing.sensor_period_s``, t = frame x h, within
:data:`STEP_RTOL`): it holds the inputs over the frame (zero-order hold), runs the frame, and the outputs
describe t + h.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cosim.fmi.export.contract import BLOCKS, CREATE, INPUT_STARTS, READOUT
from cosim.runtime.lockstep import InProcessRing
from cosim.runtime.specs import DEFAULT_SPECS, ParticipantSpec, build_schema, load_callable
from cosim.scenario.config import Scenario
from cosim.scenario.loader import load_scenario
from shm_schema import Segment

__all__ = ["SCENARIO_FILE", "STEP_RTOL", "Var", "inputs", "outputs", "WorldHost", "StepRefused"]

#: the scenario inside the FMU's resources folder
SCENARIO_FILE = "scenario.yaml"
#: relative tolerance on the communication point and step size (of one sensor period)
STEP_RTOL = 1e-6
#: frames the in-process ring is sized for: the world runs as long as the master steps it
MAX_FRAMES = 2**40
#: the dynamics role when the vehicles and the controller are outside
EXTERNAL_DYNAMICS = ParticipantSpec("dynamics", CREATE, BLOCKS)


class StepRefused(ValueError):
    """A ``doStep`` the exported world cannot take (wrong time or step size); the message says what it needs."""


@dataclass(frozen=True)
class Var:
    """One FMU variable: our ``name``, its ``kind`` (``Real``, ``Integer``, ``Boolean``), ``size`` (1, or N for a
    per-section one), ``doc`` (with units) and, for an input, its ``start`` value."""

    name: str
    kind: str
    size: int
    doc: str
    start: float | bool | None = None


_INPUT_DOCS = {
    "combine": "combine body origin (world, m) and heading (rad)", "tractor": "tractor body origin and heading",
    "cart": "cart body origin (interior centre, on the ground) and heading", "spout": "auger spout, world, m",
}


def inputs(s: Scenario) -> list[Var]:
    """The FMU's inputs, start values at the scenario's initial state (auger off, no flow)."""
    out = []
    for name, value in load_callable(INPUT_STARTS)(s).items():
        if name == "auger_on":
            out.append(Var(name, "Boolean", 1, "the auger runs", bool(value)))
        elif name == "flow_m3ps":
            out.append(Var(name, "Real", 1, "grain flow leaving the spout, m^3/s (>= 0)", float(value)))
        else:
            out.append(Var(name, "Real", 1, _INPUT_DOCS[name.split("_")[0]], float(value)))
    return out


def outputs(s: Scenario) -> list[Var]:
    """The FMU's outputs for scenario ``s`` (N = ``controller.sections`` for the per-section ones)."""
    n = s.controller.sections
    return [
        Var("frame", "Integer", 1, "frame the outputs describe (t / timing.sensor_period_s)"),
        Var("perceived_height_m", "Real", n, "perceived robust peak height of each section above the floor, m (NaN: "
                                             "too few valid cells, or the cart not found)"),
        Var("perceived_fullness", "Real", n, "perceived peak / controller.target_fill_m per section (NaN unknown)"),
        Var("perceived_cart_valid", "Boolean", 1, "perception found the cart this frame"),
        Var("perceived_cart_x_m", "Real", 1, "perceived cart body origin, world, m"),
        Var("perceived_cart_y_m", "Real", 1, "perceived cart body origin, world, m"),
        Var("perceived_cart_yaw_rad", "Real", 1, "perceived cart heading, world, rad"),
        Var("perceived_impact_valid", "Boolean", 1, "perception found the stream's impact"),
        Var("perceived_impact_gx_m", "Real", 1, "perceived impact point, cart grid x, m"),
        Var("perceived_impact_gy_m", "Real", 1, "perceived impact point, cart grid y, m"),
        Var("coverage", "Real", 1, "fraction of controller-grid cells with a perceived height"),
        Var("true_height_m", "Real", n, "true robust peak height of each section, m"),
        Var("true_fullness", "Real", n, "true peak / controller.target_fill_m per section"),
        Var("true_mean_height_m", "Real", n, "true mean grain height of each section above the floor, m"),
        Var("true_impact_valid", "Boolean", 1, "grain is in the air"),
        Var("true_impact_gx_m", "Real", 1, "true impact point, cart grid x, m"),
        Var("true_impact_gy_m", "Real", 1, "true impact point, cart grid y, m"),
        Var("delivered_m3", "Real", 1, "grain delivered since t = 0, m^3"),
        Var("in_cart_m3", "Real", 1, "grain added to the cart since t = 0, m^3"),
        Var("spilled_m3", "Real", 1, "grain spilled since t = 0, m^3"),
        Var("peak_height_m", "Real", 1, "highest grain cell above the floor, m"),
    ]


class WorldHost:
    """The exported world: ``inputs`` (name -> value, set by the FMU's setters, held over each frame),
    :meth:`start` (frame 0), :meth:`step` (one frame), ``outputs`` (name -> float or list of N floats),
    :meth:`close`. ``resources``: the folder holding ``scenario.yaml`` (the FMU's resources)."""

    def __init__(self, resources: str | Path):
        self.scenario = load_scenario(Path(resources) / SCENARIO_FILE)
        s = self.scenario
        self.period_s = s.timing.sensor_period_s
        self.inputs: dict[str, float | bool] = {v.name: v.start for v in inputs(s)}
        self.outputs: dict[str, object] = {v.name: ([math.nan] * v.size if v.size > 1 else
                                                    (False if v.kind == "Boolean" else 0 if v.kind == "Integer"
                                                     else math.nan)) for v in outputs(s)}
        self.frame = -1
        self._ring: InProcessRing | None = None
        self._participants: list = []
        self._seg: Segment | None = None

    def start(self) -> None:
        """Set up the ring and run frame 0 with the current inputs."""
        s = self.scenario
        specs = [EXTERNAL_DYNAMICS] + [DEFAULT_SPECS[n] for n in s.participants if n != "dynamics"]
        self._seg = Segment.local(build_schema(s, specs), frames=MAX_FRAMES)
        try:
            for spec in specs:
                p = spec.create(s)
                self._participants.append(p)
                p.start(self._seg)
        except BaseException:
            self.close()
            raise
        self._sections = load_callable(READOUT)(s)
        self._ring = InProcessRing(self._seg, self._participants, MAX_FRAMES)
        self._run_frame()

    def step(self, t_s: float, h_s: float) -> None:
        """One frame from ``t_s`` over ``h_s`` (one sensor period from the current frame's time, else
        :class:`StepRefused`)."""
        if self._ring is None:
            raise StepRefused("doStep before the FMU was initialised")
        tol = STEP_RTOL * self.period_s
        if abs(h_s - self.period_s) > tol:
            raise StepRefused(f"doStep with step size {h_s:g} s: the exported world takes one sensor frame per "
                              f"doStep, a step size of timing.sensor_period_s = {self.period_s:g} s")
        want = self.frame * self.period_s
        if abs(t_s - want) > tol:
            raise StepRefused(f"doStep from t = {t_s:g} s: the world stands at t = {want:g} s (frame {self.frame})")
        self._run_frame()

    def _run_frame(self) -> None:
        dyn = self._participants[0]
        dyn.set_inputs(**{k: (bool(v) if k == "auger_on" else float(v)) for k, v in self.inputs.items()})
        self.frame = self._ring.step()
        self._read_outputs()

    def _read_outputs(self) -> None:
        seg, r, o = self._seg, self._sections, self.outputs
        dyn = self._participants[0]
        truth = r.truth_peaks(dyn)
        ps = seg.view("perc_state")
        valid = bool(ps.cart_valid) and seg.frame_of("perc_state") == self.frame
        perceived = r.perceived_peaks(seg.view("heightmap_perceived")) if valid else np.full(r.sections, np.nan)
        st = seg.view("dyn_state")
        o.update({
            "frame": self.frame,
            "perceived_height_m": perceived.tolist(), "perceived_fullness": (perceived / r.target_m).tolist(),
            "perceived_cart_valid": valid, "perceived_cart_x_m": float(ps.cart_x_m),
            "perceived_cart_y_m": float(ps.cart_y_m), "perceived_cart_yaw_rad": float(ps.cart_yaw_rad),
            "perceived_impact_valid": bool(ps.impact_valid), "perceived_impact_gx_m": float(ps.impact_gx_m),
            "perceived_impact_gy_m": float(ps.impact_gy_m), "coverage": float(ps.coverage),
            "true_height_m": truth.tolist(), "true_fullness": (truth / r.target_m).tolist(),
            "true_mean_height_m": r.true_means(dyn).tolist(),
            "true_impact_valid": bool(st.impact_valid), "true_impact_gx_m": float(st.impact_gx_m),
            "true_impact_gy_m": float(st.impact_gy_m), "delivered_m3": float(st.delivered_m3),
            "in_cart_m3": float(st.in_cart_m3), "spilled_m3": float(st.spilled_m3),
            "peak_height_m": float(st.peak_height_m),
        })

    def close(self) -> None:
        """Close every participant (idempotent)."""
        participants, self._participants = self._participants, []
        for p in participants:
            p.close()
        self._ring = None
