"""The pipelined schedule (``timing.schedule: pipelined``, docs/architecture.md): each ring member waits for
exactly the (member, frame) pairs it reads.

The token ring (cosim.runtime.lockstep) passes one token dynamics -> renderer -> perception -> supervisor, so a
frame costs the sum of its members' turns (perception overlapping the next frame). Here every data edge is a
pair of counting semaphores: a producer releases ``ready`` when it has published a frame its consumer reads, and
the consumer releases ``taken`` once it has read it. Edges come from the specs' ``reads(scenario) ->
{producer: lag}`` (a consumer at frame m reads its producer's frame m - lag; cosim.runtime.participant); the
supervisor reads every member at lag 0. A member:

1. waits ``ready`` for each input frame it reads, and checks its producer's blocks carry that frame;
2. steps; at its first write of the frame (the segment's ``write_gate``) it gives ``taken`` back for its inputs
   (every input must be read by then, cosim.runtime.participant) and waits until every consumer has taken its
   previous frame, so that it never writes over a frame still unread; an overlapping member (its step returns
   its rest) gives its inputs back when the step returns and publishes with ``flush()`` after the rest;
3. releases ``ready`` to its consumers.

So each block holds one frame at a time, and the frames in flight are the readers' own copies: a producer runs
up to one frame ahead of its slowest reader. At latency L >= 2 dynamics of frame k + 2, the renderer of k + 1 and
perception of k can run at once; at L = 1, dynamics of frame k + 1 runs beside the renderer of k, which needs
P(k - 1) and S(k) only. Every wait is sliced (``POLL_S``) to check liveness and stops; in a launched run it has no
wall-clock deadline (the launcher's liveness watch judges progress, cosim.runtime.liveness), and an in-process
caller's deadline names the waiting member, the frame and the member it waits for. Data flow is the token ring's, so results are byte-identical.
"""
from __future__ import annotations

import os
import time
from dataclasses import dataclass
from typing import Callable, Mapping, Sequence

from cosim.errors import FrameMismatch, HandoffTimeout
from shm_schema import Phase, Segment
from shm_schema.layout import SLOT_WORD

from .lockstep import describe_stall, wait_for

__all__ = ["Edge", "Gates", "PipePlan", "effective_schedule", "member_loop", "supervise"]

_PHASE, _FRAME = SLOT_WORD["phase"], SLOT_WORD["frame"]
_HEARTBEAT, _STEP = SLOT_WORD["heartbeat_ns"], SLOT_WORD["step_ns"]


@dataclass(frozen=True)
class Edge:
    """``consumer`` at frame m reads ``producer``'s frame m - ``lag``."""

    producer: str
    consumer: str
    lag: int

    @property
    def key(self) -> str:
        return f"{self.producer}>{self.consumer}"


@dataclass(frozen=True)
class PipePlan:
    """Members (in ring order), frames 0..``frames``, the data edges (the supervisor's included), the members whose
    step returns its rest (published by ``flush()``) and whether the supervisor keeps every frame until its
    sinks have seen it (``hold``: a sink reads the segment's blocks at the frame it is given)."""

    members: tuple[str, ...]
    frames: int
    edges: tuple[Edge, ...]
    supervisor: str = "supervisor"
    deferred: tuple[str, ...] = ()
    hold: bool = False

    @classmethod
    def build(cls, reads: Mapping[str, Mapping[str, int]], frames: int, *, supervisor: str = "supervisor",
              deferred: Sequence[str] = (), hold: bool = False) -> "PipePlan":
        """The plan of members ``reads`` (member -> {producer: lag}, in ring order). Raises ValueError for an
        unknown producer, a negative lag, or members that wait for each other's same frame (a lag-0 cycle)."""
        members = tuple(reads)
        edges = []
        for consumer, ins in reads.items():
            for producer, lag in ins.items():
                if producer not in members or producer == consumer:
                    raise ValueError(f"{consumer} reads {producer!r}, which is not another member of {members}")
                if int(lag) < 0:
                    raise ValueError(f"{consumer} reads {producer} {lag} frames back: a lag must be >= 0")
                edges.append(Edge(producer, consumer, int(lag)))
        _check_acyclic(members, edges)
        edges += [Edge(m, supervisor, 0) for m in members]
        return cls(members, frames, tuple(edges), supervisor, tuple(m for m in members if m in deferred), hold)

    def inputs(self, name: str) -> tuple[Edge, ...]:
        return tuple(e for e in self.edges if e.consumer == name)

    def outputs(self, name: str) -> tuple[Edge, ...]:
        return tuple(e for e in self.edges if e.producer == name)

    def read(self, edge: Edge, frame: int) -> bool:
        """Whether ``edge``'s consumer reads its producer's ``frame`` (0 <= frame and frame + lag <= frames)."""
        return 0 <= frame and frame + edge.lag <= self.frames

    @property
    def semaphore_names(self) -> tuple[str, ...]:
        return tuple(f"{kind}:{e.key}" for e in self.edges for kind in ("ready", "taken"))


def _check_acyclic(members: tuple[str, ...], edges: list[Edge]) -> None:
    after = {m: {e.consumer for e in edges if e.producer == m and e.lag == 0} for m in members}
    state: dict[str, int] = {}

    def visit(m: str, path: tuple[str, ...]) -> None:
        if state.get(m) == 1:
            raise ValueError(f"members wait for each other's same frame: {' -> '.join(path + (m,))}")
        if state.get(m) == 2:
            return
        state[m] = 1
        for n in after[m]:
            visit(n, path + (m,))
        state[m] = 2

    for m in members:
        visit(m, ())


def effective_schedule(scenario, reads: Mapping[str, Mapping[str, int] | None]) -> tuple[str, str]:
    """(schedule, why) a launched run uses: ``pipelined`` for ``timing.schedule: pipelined``, else ``sequential`` (the
    token ring; ``overlapped`` is the token ring with perception overlapping), and ``sequential`` where pipelining cannot pay
    or cannot be planned: one ring member, one core, or a member without a ``reads`` declaration."""
    want = scenario.timing.schedule
    if want != "pipelined":
        return "sequential", f"timing.schedule: {want}"
    if len(reads) < 2:
        return "sequential", "one ring member: nothing to pipeline"
    missing = [m for m, r in reads.items() if r is None]
    if missing:
        return "sequential", f"no reads declared for {', '.join(missing)}"
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    if cores < 2:
        return "sequential", "one core"
    return "pipelined", f"{cores} cores"


class Gates:
    """One process's side of the plan's semaphores (``sems``: name -> semaphore, :attr:`PipePlan.semaphore_names`)
    for member ``me``; ``check`` runs between wait slices and raises to abort (a dead peer, a stop)."""

    def __init__(self, seg: Segment, plan: PipePlan, sems: Mapping[str, object], me: str,
                 check: Callable[[], None] | None = None):
        self.seg, self.plan, self.me, self.check = seg, plan, me, check
        self._sems = dict(sems)
        self._inputs, self._outputs = plan.inputs(me), plan.outputs(me)
        self._blocks = {m: [b.name for b in seg.schema.blocks if b.writer == m] for m in plan.members}

    def _wait(self, name: str, timeout_s: float | None, what: str, frame: int) -> None:
        wait_for(self._sems[name], timeout_s, self.check,
                 lambda: HandoffTimeout(f"{self.me} waited {timeout_s:g} s for {what}: "
                                        + describe_stall(self.seg, exclude=self.me), process=self.me, frame=frame))

    def take(self, edge: Edge, frame: int, timeout_s: float) -> None:
        """Wait until ``edge``'s producer has published ``frame`` (its blocks' newest stamp must say so)."""
        self._wait(f"ready:{edge.key}", timeout_s, f"{edge.producer}'s frame {frame}", frame)
        stamps = [self.seg.frame_of(b) for b in self._blocks[edge.producer]]
        if stamps and max(stamps) != frame:
            raise FrameMismatch(f"{self.me} expected {edge.producer}'s frame {frame} but its blocks hold frame "
                                f"{max(stamps)}", process=self.me, frame=frame)

    def give_back(self, edge: Edge) -> None:
        """``edge``'s consumer has read the frame: the producer may write its next one."""
        self._sems[f"taken:{edge.key}"].release()

    def take_inputs(self, frame: int, timeout_s: float) -> None:
        for e in self._inputs:
            if self.plan.read(e, frame - e.lag):
                self.take(e, frame - e.lag, timeout_s)

    def give_inputs(self, frame: int) -> None:
        for e in self._inputs:
            if self.plan.read(e, frame - e.lag):
                self.give_back(e)

    def free_outputs(self, frame: int, timeout_s: float) -> None:
        """Wait until every consumer that reads this member's ``frame - 1`` has taken it."""
        for e in self._outputs:
            if self.plan.read(e, frame - 1):
                self._wait(f"taken:{e.key}", timeout_s, f"{e.consumer} to read frame {frame - 1}", frame)

    def give_outputs(self, frame: int) -> None:
        for e in self._outputs:
            if self.plan.read(e, frame):
                self._sems[f"ready:{e.key}"].release()


class _FrameGate:
    """The segment's write gate for one frame of one member: at the first write (or when called), inputs given
    back, then the wait for the outputs to be free."""

    __slots__ = ("_gates", "_frame", "_timeout", "_words", "_inputs", "_outputs", "waited_ns")

    def __init__(self, gates: Gates, frame: int, timeout_s: float, words):
        self._gates, self._frame, self._timeout, self._words = gates, frame, timeout_s, words
        self._inputs = self._outputs = False
        #: time spent waiting for the readers (not the member's work), ns
        self.waited_ns = 0

    def inputs_read(self) -> None:
        if not self._inputs:
            self._inputs = True
            self._gates.give_inputs(self._frame)

    def __call__(self) -> None:
        self.inputs_read()
        if not self._outputs:
            self._outputs = True
            self._words[_PHASE] = Phase.WAITING
            t0 = time.monotonic_ns()
            self._gates.free_outputs(self._frame, self._timeout)
            self.waited_ns = time.monotonic_ns() - t0
            self._words[_PHASE] = Phase.STEPPING


def member_loop(name: str, participant, seg: Segment, gates: Gates, plan: PipePlan, *,
                startup_timeout_s: float | None, handoff_timeout_s: float | None) -> None:
    """Run one member for frames 0..plan.frames under the pipelined schedule (the module docstring)."""
    w = seg.slot_words(name)
    clock = time.monotonic_ns
    step = participant.step
    deferred = name in plan.deferred
    try:
        for frame in range(plan.frames + 1):
            timeout = startup_timeout_s if frame == 0 else handoff_timeout_s
            w[_PHASE] = Phase.WAITING
            gates.take_inputs(frame, timeout)
            w[_FRAME] = frame
            w[_PHASE] = Phase.STEPPING
            t0 = w[_HEARTBEAT] = clock()
            gate = seg.write_gate = _FrameGate(gates, frame, handoff_timeout_s, w)
            rest = step(frame)
            if rest is not None:
                if not deferred:
                    raise RuntimeError(f"{name} returned work to run after its turn, but the plan does not defer "
                                       "its outputs (ParticipantSpec.defers)")
                gate.inputs_read()
                rest()
                gate()
                participant.flush()
            gate()
            seg.write_gate = None
            t1 = w[_HEARTBEAT] = clock()
            w[_STEP] = t1 - t0 - gate.waited_ns             # the member's own work, as in the token ring
            gates.give_outputs(frame)
    finally:
        seg.write_gate = None
    w[_PHASE] = Phase.DONE


def supervise(seg: Segment, plan: PipePlan, gates: Gates, *, startup_timeout_s: float | None,
              handoff_timeout_s: float | None,
              on_take: Callable[[str, int], None], on_frame: Callable[[int, int], None]) -> None:
    """The supervisor's side: for every frame, each member's outputs as soon as published (``on_take(member,
    frame)``, then given back unless ``plan.hold``), then ``on_frame(frame, turn_ns)`` (turn_ns: since the
    previous frame completed; given back after it with ``hold``)."""
    sw = seg.slot_words(plan.supervisor)
    edges = plan.inputs(plan.supervisor)
    t_prev = time.monotonic_ns()
    for frame in range(plan.frames + 1):
        timeout = None if handoff_timeout_s is None else handoff_timeout_s + (startup_timeout_s if frame == 0 else 0.0)
        for e in edges:
            sw[_PHASE] = Phase.WAITING
            gates.take(e, frame, timeout)
            sw[_PHASE] = Phase.STEPPING
            on_take(e.producer, frame)
            if not plan.hold:
                gates.give_back(e)
        now = time.monotonic_ns()
        sw[_FRAME] = frame
        on_frame(frame, now - t_prev)
        t_prev = now
        if plan.hold:
            for e in edges:
                gates.give_back(e)
        sw[_HEARTBEAT] = time.monotonic_ns()
    sw[_PHASE] = Phase.DONE
