"""The lockstep token ring (docs/architecture.md).

One turn per frame: dynamics -> renderer -> perception -> supervisor -> dynamics ... Each member blocks on its
own semaphore; the sender writes the frame id into the receiver's header slot before releasing it, and the
receiver checks it. Waits are sliced (``POLL_S``) to check liveness between slices; nothing spins and nothing
sleeps to synchronise. In a launched run no wait has a wall-clock deadline: the launcher's liveness watch
(cosim.runtime.liveness) names a member that makes no progress, so a slow member on a busy machine is waited for;
in-process callers may give a deadline, which raises a named error. A deferred member
(``RingPlan.deferred``, see cosim.runtime.participant) passes the token on before the rest of its step, so its work
overlaps the next members' turns; a flush turn after the last frame lets it publish its final outputs.

The same member code runs over OS processes (:class:`Token` over multiprocessing semaphores) or in one process
(:class:`InProcessRing`, the ring unrolled into a loop stepped a frame at a time).
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable, Mapping, Sequence

from cosim.errors import FrameMismatch, HandoffTimeout
from shm_schema import Phase, Segment
from shm_schema.layout import SLOT_WORD

_TOKEN, _PHASE, _FRAME = SLOT_WORD["token"], SLOT_WORD["phase"], SLOT_WORD["frame"]
_HEARTBEAT, _STEP = SLOT_WORD["heartbeat_ns"], SLOT_WORD["step_ns"]

__all__ = ["POLL_S", "RingPlan", "Token", "member_loop", "describe_stall", "wait_for", "InProcessRing", "run_inprocess"]

#: slice of every blocking wait, s: bounds how late a dead peer or a stop request is noticed
POLL_S = 0.05


@dataclass(frozen=True)
class RingPlan:
    """Ring order and length. ``members`` are the participants in ring order; the supervisor closes the ring."""

    members: tuple[str, ...]
    frames: int
    supervisor: str = "supervisor"
    #: members that publish one turn late (cosim.runtime.participant): after the last frame a flush turn passes the
    #: token through them, in ring order, and back to the supervisor
    deferred: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        unknown = [n for n in self.deferred if n not in self.members]
        if unknown:
            raise ValueError(f"deferred members {unknown} are not in the ring {self.members}")
        object.__setattr__(self, "deferred", tuple(n for n in self.members if n in self.deferred))

    def next_of(self, name: str) -> str:
        """Who receives the token after ``name``."""
        if name == self.supervisor:
            return self.members[0]
        i = self.members.index(name)
        return self.members[i + 1] if i + 1 < len(self.members) else self.supervisor

    @property
    def flush_frame(self) -> int | None:
        """Frame id of the flush turn (one past the last frame), or None when no member defers."""
        return self.frames + 1 if self.deferred else None

    def flush_next_of(self, name: str) -> str:
        """Who receives the flush turn's token after ``name`` (the supervisor starts it)."""
        if name == self.supervisor:
            return self.deferred[0]
        i = self.deferred.index(name)
        return self.deferred[i + 1] if i + 1 < len(self.deferred) else self.supervisor


class Token:
    """Hand-offs over one semaphore per receiver; the frame id rides in the receiver's header slot."""

    def __init__(self, segment: Segment, semaphores: Mapping[str, object]):
        self._seg = segment
        self._sems = dict(semaphores)
        self._words = {name: segment.slot_words(name) for name in self._sems}

    def give(self, to: str, frame: int) -> None:
        self._words[to][_TOKEN] = frame
        self._sems[to].release()

    def take(self, me: str, frame: int, timeout_s: float | None, check: Callable[[], None] | None = None) -> None:
        """Block until ``me`` holds the token for ``frame``.

        ``check`` runs between wait slices and raises to abort (a dead or hung peer, a stop request: the
        launcher's liveness watch). ``timeout_s`` None waits as long as ``check`` lets it (the launched ring:
        progress, not the clock, decides); a number raises :class:`HandoffTimeout` after that long (in-process
        tests). Raises :class:`FrameMismatch` for a token of another frame.
        """
        wait_for(self._sems[me], timeout_s, check,
                 lambda: HandoffTimeout(f"{me} waited {timeout_s:g} s for the token of frame {frame}: "
                                        + describe_stall(self._seg, exclude=me), process=me, frame=frame))
        self._check_frame(me, frame)

    def _check_frame(self, me: str, frame: int) -> None:
        got = self._words[me][_TOKEN]
        if got != frame:
            raise FrameMismatch(f"{me} expected the token of frame {frame} but received frame {got}",
                                process=me, frame=frame)


def wait_for(sem, timeout_s: float | None, check: Callable[[], None] | None,
             timed_out: Callable[[], Exception]) -> None:
    """Acquire ``sem`` in ``POLL_S`` slices, running ``check`` between them; after ``timeout_s`` (None: never)
    raise ``timed_out()``."""
    if sem.acquire(timeout=POLL_S):
        return
    deadline = None if timeout_s is None else time.monotonic() + timeout_s - POLL_S
    if check is not None:
        check()
    while True:
        left = POLL_S if deadline is None else min(POLL_S, max(0.0, deadline - time.monotonic()))
        if sem.acquire(timeout=left):
            return
        if check is not None:
            check()
        if deadline is not None and time.monotonic() >= deadline:
            raise timed_out()


def describe_stall(seg: Segment, exclude: str = "") -> str:
    """Say which process holds up the ring, from the header slots (phase, frame, heartbeat age)."""
    now = time.monotonic_ns()
    parts = []
    for name in seg.schema.participants:
        if name == exclude:
            continue
        s = seg.slot(name)
        phase = int(s["phase"])
        age = (now - int(s["heartbeat_ns"])) / 1e9 if int(s["heartbeat_ns"]) else float("nan")
        label = Phase.NAMES[phase] if 0 <= phase < len(Phase.NAMES) else str(phase)
        parts.append(f"{name} is {label} frame {int(s['frame'])} (pid {int(s['pid'])}, for {age:.2f} s)")
    stuck = [p for p in parts if " is stepping " in p or " is starting " in p]
    return "; ".join(stuck or parts)


def member_loop(name: str, participant, seg: Segment, token: Token, plan: RingPlan, *,
                startup_timeout_s: float | None, handoff_timeout_s: float | None, check: Callable[[], None] | None = None) -> None:
    """Run one ring member for frames 0..plan.frames: take the token, step, pass it on; a deferred member runs
    the rest of its step after passing the token, and takes part in the flush turn at the end."""
    w = seg.slot_words(name)
    nxt = plan.next_of(name)
    clock = time.monotonic_ns
    step = participant.step
    deferred = name in plan.deferred
    for frame in range(plan.frames + 1):
        w[_PHASE] = Phase.WAITING
        token.take(name, frame, startup_timeout_s if frame == 0 else handoff_timeout_s, check)
        w[_FRAME] = frame
        w[_PHASE] = Phase.STEPPING
        t0 = w[_HEARTBEAT] = clock()
        rest = step(frame)
        if rest is not None:
            _check_deferred(name, deferred)
            token.give(nxt, frame)
            rest()
        t1 = w[_HEARTBEAT] = clock()
        w[_STEP] = t1 - t0
        if rest is None:
            token.give(nxt, frame)
    if deferred:
        flush = plan.flush_frame
        w[_PHASE] = Phase.WAITING
        token.take(name, flush, handoff_timeout_s, check)
        w[_FRAME] = flush
        w[_PHASE] = Phase.STEPPING
        w[_HEARTBEAT] = clock()
        participant.flush()
        w[_HEARTBEAT] = clock()
        token.give(plan.flush_next_of(name), flush)
    w[_PHASE] = Phase.DONE


def _check_deferred(name: str, deferred: bool) -> None:
    if not deferred:
        raise RuntimeError(f"{name} returned work to run after its turn, but the ring plan does not defer its "
                           "outputs (ParticipantSpec.defers)")


class InProcessRing:
    """The ring unrolled in one process and stepped a frame at a time (``simulate`` and ``cosim.Simulation``).

    :meth:`step` does one turn: every participant in order (a deferred member's rest right after its step),
    then ``on_frame(frame)``; the turn of the last frame also runs the flush turn of the ``deferred`` members
    and ``on_flush``. Every block is read and written at the same point of the token order as in the process
    ring, so both give the same results. Participants must already be started. Header slots are kept as in
    the OS-process ring so that recorders and diagnostics read the same fields. ``current`` names the member
    stepping (or that raised), ``None`` between turns.
    """

    def __init__(self, seg: Segment, participants: Sequence, frames: int,
                 on_frame: Callable[[int], None] | None = None, *, deferred: Sequence[str] = (),
                 on_flush: Callable[[], None] | None = None):
        self.participants = tuple(participants)
        self.frames = frames
        self.deferred = tuple(deferred)
        self._slots = [seg.slot(p.name) for p in self.participants]
        self._on_frame, self._on_flush = on_frame, on_flush
        #: the frame the next :meth:`step` runs (``frames + 1`` once the ring is done)
        self.next_frame = 0
        self.current: str | None = None
        self.turn_ns = 0

    @property
    def done(self) -> bool:
        """Whether the last frame (and the flush turn) has run."""
        return self.next_frame > self.frames

    def step(self) -> int:
        """Run the next frame's turn (and, after the last frame, the flush turn); return the frame id."""
        frame = self.next_frame
        if frame > self.frames:
            raise RuntimeError(f"the ring has run all its {self.frames + 1} frames")
        clock = time.monotonic_ns
        t_turn = clock()
        for p, slot in zip(self.participants, self._slots):
            self.current = p.name
            slot["frame"] = frame
            slot["phase"] = Phase.STEPPING
            t0 = clock()
            rest = p.step(frame)
            if rest is not None:
                _check_deferred(p.name, p.name in self.deferred)
                rest()
            slot["step_ns"] = clock() - t0
            slot["phase"] = Phase.WAITING
        self.current = None
        self.turn_ns = clock() - t_turn
        if self._on_frame is not None:
            self._on_frame(frame)
        if frame == self.frames and self.deferred:
            for p, slot in zip(self.participants, self._slots):
                if p.name in self.deferred:
                    self.current = p.name
                    slot["frame"] = frame + 1
                    p.flush()
            self.current = None
            if self._on_flush is not None:
                self._on_flush()
        self.next_frame = frame + 1
        return frame


def run_inprocess(seg: Segment, participants: Sequence, frames: int,
                  on_frame: Callable[[int], None] | None = None, *, deferred: Sequence[str] = (),
                  on_flush: Callable[[], None] | None = None) -> None:
    """Run every frame of an :class:`InProcessRing` (frames 0..``frames``, then the flush turn)."""
    ring = InProcessRing(seg, participants, frames, on_frame, deferred=deferred, on_flush=on_flush)
    while not ring.done:
        ring.step()
