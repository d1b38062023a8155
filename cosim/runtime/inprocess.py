"""The in-process transport: the same participants and recorder as a launched run, in one process.

For tests and debugging (a debugger and a profiler see every participant). No shared memory under /dev/shm:
the segment lives in ordinary memory.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Mapping

from shm_schema import Segment

from cosim.scenario.config import Scenario
from .lockstep import run_inprocess
from .recorder import Recorder
from .specs import ParticipantSpec, build_schema, ring_specs

__all__ = ["InProcessRun", "simulate"]


@dataclass
class InProcessRun:
    """Result of :func:`simulate`: the recorder (timeseries, final arrays), the segment and the wall time."""

    recorder: Recorder
    segment: Segment
    wall_time_s: float
    ring: list[ParticipantSpec]


def simulate(scenario: Scenario, specs: Mapping[str, ParticipantSpec] | None = None,
             frames: int | None = None, progress=None) -> InProcessRun:
    """Run ``scenario`` in this process for ``frames`` frames (default: the whole scenario). ``progress``: called
    ``(frame, frames, sim_s, wall_s)`` after each frame, like the launcher's (cosim.runtime.progress)."""
    ring = ring_specs(scenario, specs)
    schema = build_schema(scenario, ring)
    n = scenario.frames if frames is None else frames
    seg = Segment.local(schema, frames=n)
    members = tuple(s.name for s in ring)
    deferred = tuple(s.name for s in ring if s.defers_outputs(scenario))
    recorder = Recorder(seg, members, deferred=bool(deferred))
    participants = []
    t0 = time.perf_counter()
    try:
        for spec in ring:
            p = spec.create(scenario)
            participants.append(p)
            p.start(seg)
        record = recorder.record
        if progress is not None:
            period = scenario.timing.sensor_period_s

            def record(frame: int, turn_ns: int | None = None) -> None:
                recorder.record(frame, turn_ns)
                progress(frame, n, frame * period, time.perf_counter() - t0)

        run_inprocess(seg, participants, n, record, deferred=deferred, on_flush=recorder.record_flush)
        recorder.finish()
    finally:
        for p in participants:
            p.close()
    return InProcessRun(recorder, seg, time.perf_counter() - t0, ring)
