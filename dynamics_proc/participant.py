"""The dynamics participant: the ring's first member, a thin shell around :mod:`dynamics_proc.model`.

``start`` binds the views, ``step(frame)`` runs one frame and publishes ``dyn_state``, ``stream`` and
``heightmap_truth``; frame 0 publishes the initial state without integrating. Feedback (CONTRACTS.md): with
``feedback: perception`` the controller reads ``heightmap_perceived`` and acts on P(m - 1 - L) at frame m
(L = ``timing.latency_frames``; a copy of each perception output is kept under its frame stamp until used, read
from the blocks at each frame: one frame later when perception overlaps, exactly P(m - 1 - L) under the
pipelined schedule; a missing or stale
output, or ``perc_state.cart_valid == 0``, is "no measurement"). With ``ground_truth`` it acts on the truth
height map of frame m - 1 - L resampled to the controller grid. The participant also keeps its own record
(``rows``, ``heights``) for in-process use. In-process, :meth:`DynamicsParticipant.set_input` changes a run-time
input (:mod:`dynamics_proc.inputs`) from the next integrated frame on.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from cosim.errors import FrameMismatch
from cosim.scenario.config import Scenario
from dynamics_proc.blocks import WRITER, state_fields
from dynamics_proc.fmu.models import Fmus, open_fmus
from dynamics_proc.inputs import INPUTS, apply_input
from dynamics_proc.model import ModelParams, World, initial_world, signals, step_frame, truth_measurement

if TYPE_CHECKING:
    from shm_schema import Segment

__all__ = ["DynamicsParticipant", "create"]


class DynamicsParticipant:
    """Ground truth of the run: vehicles, auger, grain, controller."""

    name = WRITER
    #: run-time inputs :meth:`set_input` takes (cosim.Simulation.set)
    settable: tuple[str, ...] = tuple(INPUTS)

    def __init__(self, scenario: Scenario):
        self.scenario = scenario
        self.params = ModelParams.from_scenario(scenario)
        self.latency = scenario.timing.latency_frames
        self.perception = scenario.feedback == "perception"
        self.world: World | None = None
        self.rows: list[dict[str, float]] = []
        self._names = tuple(f.name for f in state_fields(scenario.controller.sections))
        self._history: dict[int, np.ndarray | None] = {}
        self._seg: Segment | None = None
        self._fmus: Fmus | None = None
        self._next = 0
        #: inputs set since the last frame (path -> value), applied before the next integration
        self._pending: dict[str, float] = {}

    # -- contract ----------------------------------------------------------------------------------------
    def start(self, segment: "Segment") -> None:
        """Bind the views this participant writes and, with perception feedback, reads; open the scenario's
        FMUs (dynamics_proc.fmu.models)."""
        self._fmus = open_fmus(self.scenario)
        if self._fmus is not None:
            self.params = ModelParams.from_scenario(self.scenario, self._fmus)
        self._seg = segment
        self._state = segment.view("dyn_state")
        self._stream = segment.view("stream")
        self._hmap = segment.view("heightmap_truth")
        got = tuple(self._state.array.dtype.names)
        if got != self._names:
            raise ValueError(f"dyn_state in the segment has fields {got}, this participant writes {self._names}")
        self._perceived = None
        if self.perception:
            if not segment.has("heightmap_perceived"):
                raise ValueError("dynamics: feedback 'perception' but the segment has no 'heightmap_perceived' "
                                 "block; is perception in the ring?")
            self._perceived = segment.view("heightmap_perceived")
            want = (self.params.control.nx, self.params.control.ny)
            if self._perceived.shape != want:
                raise ValueError(f"dynamics: heightmap_perceived is {self._perceived.shape}, the controller grid "
                                 f"(controller.grid_cell_m = {self.params.control.grid_cell_m} m) is {want}")
        ps = segment.view("perc_state") if self.perception and segment.has("perc_state") else None
        self._cart_valid = ps if ps is not None and "cart_valid" in ps.array.dtype.names else None

    def step(self, frame: int) -> None:
        """Frame 0: publish the initial state. Frame m >= 1: integrate t_{m-1} -> t_m, then publish."""
        if self._seg is None:
            raise RuntimeError("dynamics: step() before start()")
        if frame != self._next:
            raise FrameMismatch(f"dynamics expected frame {self._next}, got {frame}", process=self.name,
                                frame=frame)
        if frame == 0:
            self.world = initial_world(self.scenario, self.params)
        else:
            if self.perception:
                # the freshest published output, kept under its own frame until used: P(frame - 1), P(frame - 2)
                # when perception overlaps, P(frame - 1 - L) under the pipelined schedule (cosim.runtime.pipeline)
                got = self._read_perception()
                if got is not None:
                    self._history[got[0]] = got[1]
            meas = self._history.pop(frame - 1 - self.latency, None)
            for k in [k for k in self._history if k < frame - 1 - self.latency]:
                del self._history[k]
            if self._pending:
                self._apply_pending()
            self.world = step_frame(self.world, meas, self.params)
        self._publish(frame)
        if not self.perception:
            self._history[frame] = truth_measurement(self.world.heights, self.params)
        self._next = frame + 1

    def close(self) -> None:
        """Drop the views (the segment belongs to the runtime) and free the FMUs."""
        if self._fmus is not None:
            self._fmus.close()
            self._fmus = None
        self._seg = None
        self._perceived = self._cart_valid = None
        self._history.clear()

    def set_input(self, path: str, value: float) -> None:
        """Set run-time input ``path`` (:data:`dynamics_proc.inputs.INPUTS`) from the next integrated frame on."""
        if path not in INPUTS:
            raise KeyError(f"{path!r} is not a run-time input; inputs: {', '.join(INPUTS)}")
        self._pending[path] = float(value)

    # -- records -----------------------------------------------------------------------------------------
    @property
    def heights(self) -> np.ndarray | None:
        """Latest truth height map (nx, ny) float64 m (None before frame 0)."""
        return None if self.world is None else self.world.heights

    def series(self) -> dict[str, np.ndarray]:
        """Own record: column ``"dyn_state.<field>"`` -> (frames,) float64."""
        return {f"dyn_state.{k}": np.array([r[k] for r in self.rows], dtype=np.float64) for k in self._names}

    # -- internals ---------------------------------------------------------------------------------------
    def _read_perception(self) -> tuple[int, np.ndarray | None] | None:
        """(frame, copy of the perceived map, or None for "no measurement") of the published perception output;
        None before the first."""
        seg = self._seg
        stamp = seg.frame_of("heightmap_perceived") if self._perceived is not None else -1
        if stamp < 0:
            return None
        if self._cart_valid is not None and (seg.frame_of("perc_state") != stamp or not self._cart_valid.cart_valid):
            return stamp, None
        return stamp, np.array(self._perceived, dtype=np.float64)

    def _apply_pending(self) -> None:
        w, p = self.world, self.params
        for path, value in self._pending.items():
            w, p = apply_input(w, p, self.scenario, path, value)
        self.world, self.params = w, p
        self._pending.clear()

    def _publish(self, frame: int) -> None:
        w, seg = self.world, self._seg
        sig = signals(w, self.params)
        self.rows.append(sig)
        with seg.write("dyn_state", frame) as v:
            v.assign([sig[n] for n in self._names])
        with seg.write("stream", frame) as s:
            s[...] = w.stream
        with seg.write("heightmap_truth", frame) as h:
            h[...] = w.heights


def create(scenario: Scenario) -> DynamicsParticipant:
    """The dynamics participant for ``scenario`` (validates the grids: ValueError on a bad cell size)."""
    return DynamicsParticipant(scenario)
