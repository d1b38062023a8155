"""The in-process transport: the same participants and recorder as a launched run, in one process.

For tests, debugging (a debugger and a profiler see every participant) and the Python API (``cosim.Simulation``,
which steps an :class:`InProcessSession` a frame at a time). No shared memory under /dev/shm: the segment lives
in ordinary memory, and nothing is spawned (it runs inside daemonic pool workers).
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable, Mapping

from cosim.scenario.config import Scenario
from shm_schema import Segment

from .lockstep import InProcessRing
from .recorder import Recorder
from .specs import ParticipantSpec, build_schema, ring_specs

__all__ = ["InProcessRun", "InProcessSession", "simulate"]


@dataclass
class InProcessRun:
    """Result of :func:`simulate`: the recorder (timeseries, final arrays), the segment and the wall time."""

    recorder: Recorder
    segment: Segment
    wall_time_s: float
    ring: list[ParticipantSpec]


class InProcessSession:
    """One in-process run, set up and ready to step: segment, started participants, recorder, ring.

    ``step()`` runs the next frame (frames 0..``frames``; the last also runs the flush turn), ``finish()``
    copies the final arrays once the ring is done or stopped, ``close()`` closes every participant (always call
    it; a participant that fails in ``create``/``start`` closes those already started). ``participants`` maps
    ring name -> participant object. ``sinks`` (append to it before stepping) are called as
    ``sink(segment, frame)`` after each recorded frame and after the flush turn (frame = last + 1), as a launched
    run's (cosim.runtime.launcher.SinkFactory).
    """

    def __init__(self, scenario: Scenario, specs: Mapping[str, ParticipantSpec] | None = None,
                 frames: int | None = None):
        self.t0 = time.perf_counter()
        self.scenario = scenario
        self.ring = ring_specs(scenario, specs)
        schema = build_schema(scenario, self.ring)
        self.frames = scenario.frames if frames is None else frames
        self.segment = Segment.local(schema, frames=self.frames)
        deferred = tuple(s.name for s in self.ring if s.defers_outputs(scenario))
        self.recorder = Recorder(self.segment, tuple(s.name for s in self.ring), deferred=bool(deferred))
        self.participants: dict[str, object] = {}
        try:
            for spec in self.ring:
                p = spec.create(scenario)
                self.participants[spec.name] = p
                p.start(self.segment)
        except BaseException:
            self.close()
            raise
        self.sinks: list[Callable] = []
        self.turns = InProcessRing(self.segment, list(self.participants.values()), self.frames, self._on_frame,
                                   deferred=deferred, on_flush=self._on_flush)

    @property
    def done(self) -> bool:
        """Whether every frame (and the flush turn) has run."""
        return self.turns.done

    def step(self) -> int:
        """Run the next frame; return its id."""
        return self.turns.step()

    def _on_frame(self, frame: int) -> None:
        self.recorder.record(frame, self.turns.turn_ns if frame > 0 else None)
        for sink in self.sinks:
            sink(self.segment, frame)

    def _on_flush(self) -> None:
        self.recorder.record_flush()
        for sink in self.sinks:
            sink(self.segment, self.frames + 1)

    def finish(self) -> InProcessRun:
        """Copy the final arrays (once the ring has stopped) and return the run's record."""
        self.recorder.finish()
        return InProcessRun(self.recorder, self.segment, time.perf_counter() - self.t0, self.ring)

    def close(self) -> None:
        """Close every participant (idempotent)."""
        participants, self.participants = self.participants, {}
        for p in participants.values():
            p.close()


def simulate(scenario: Scenario, specs: Mapping[str, ParticipantSpec] | None = None,
             frames: int | None = None, progress=None) -> InProcessRun:
    """Run ``scenario`` in this process for ``frames`` frames (default: the whole scenario). ``progress``: called
    ``(frame, frames, sim_s, wall_s)`` after each frame, like the launcher's (cosim.runtime.progress)."""
    session = InProcessSession(scenario, specs, frames)
    period = scenario.timing.sensor_period_s
    try:
        while not session.done:
            frame = session.step()
            if progress is not None and frame <= session.frames:
                progress(frame, session.frames, frame * period, time.perf_counter() - session.t0)
        return session.finish()
    finally:
        session.close()
