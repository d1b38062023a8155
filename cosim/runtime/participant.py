"""The participant contract: one frame-stepped component of the ring.

A participant is created from the scenario, started with the run's segment, then stepped once per frame in
ring order (dynamics -> renderer -> perception). The same object runs in-process (tests, debugging:
``cosim.runtime.lockstep.run_inprocess``) or inside an OS process over shared memory (``cosim.runtime.launcher``); it never
knows which. It must not synchronise, sleep or spin: the ring calls ``step`` when its turn comes.

Frame ids: frame 0 publishes the initial state (dynamics does not integrate); at frame m >= 1 dynamics
integrates t_{m-1} -> t_m and writes S(m), the renderer renders S(m) into I(m) and perception turns I(m) into
P(m). Feedback latency L (``timing.latency_frames``): at frame m dynamics acts on P(m - 1 - L), i.e. L frames
older than the freshest perception output (P(m-1)). Outputs for frames < 0 do not exist: "no measurement".

Overlap (``timing.schedule`` other than ``sequential``, :func:`perception_overlaps`): when dynamics does not need P(m) before
frame m + 2, perception splits its frame. ``step(m)`` first publishes P(m - 1), kept from its previous turn,
then gathers what it needs from I(m) and returns the rest of its work as a callable; the ring passes the token
on and then runs that callable, which computes P(m) into private memory while dynamics and the renderer do
frame m + 1. So at the supervisor's turn of frame m the perception blocks hold P(m - 1) (their stamps say so)
and a last turn, after frame N, runs only ``flush()`` (publish P(N)) and the supervisor. Every block is read
and written at the same point of the token order in a process ring and in-process, so the results are
identical, and identical to the serial ring.

Pipelined schedule (``timing.schedule: pipelined``, ``cosim.runtime.pipeline``): each member waits only for the
(member, frame) pairs it reads, declared by its spec's ``reads(scenario) -> {producer: lag}`` (at frame m it reads
the producer's frame m - lag; :func:`dynamics_reads`, :func:`renderer_reads`, :func:`perception_reads`). A member
must read every input of a frame before it writes its first output of that frame (a producer may then write its
next frame over them), and an overlapping member must have read them when ``step`` returns its rest.

Each package exposes ``declare_blocks(scenario) -> list[Block]`` (``<pkg>/blocks.py``) and
``create(scenario) -> Participant`` (``<pkg>/participant.py``).
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Callable, Protocol, runtime_checkable

if TYPE_CHECKING:
    from shm_schema.segment import Segment

__all__ = ["Participant", "PARTICIPANTS", "activity", "set_activity", "PERCEPTION_TAKEN_FRAMES_BACK", "dynamics_reads", "perception_overlaps",
           "perception_reads", "renderer_reads"]

#: every participant name, in ring order
PARTICIPANTS: tuple[str, ...] = ("dynamics", "renderer", "perception")


@runtime_checkable
class Participant(Protocol):
    """One ring member. ``name`` is one of :data:`PARTICIPANTS` and the ``writer`` of its blocks."""

    name: str

    def start(self, segment: "Segment") -> None:
        """Bind views of the blocks it reads and writes; heavy set-up (GL context, tables) goes here."""

    def step(self, frame: int) -> "Callable[[], None] | None":
        """Do frame ``frame``: read inputs, compute, write outputs with ``segment.write(block, frame)``. A member
        that overlaps returns the rest of its work, run after the token has moved on; others return None."""

    def close(self) -> None:
        """Release resources (GL context, files). Called once, also after a failure."""


def perception_overlaps(scenario) -> bool:
    """Whether perception publishes one turn late and overlaps the next frame (see the module docstring).

    Only when nothing needs P(m) at frame m + 1: dynamics acts on P(m - 1 - L), so any latency L >= 1 leaves
    a frame of slack, and ground-truth feedback reads no perception output at all."""
    t = scenario.timing
    return t.schedule != "sequential" and (scenario.feedback != "perception" or t.latency_frames >= 1)


#: the most frames back dynamics takes perception's outputs under the pipelined schedule: it acts on
#: P(m - 1 - L) and keeps each output from the frame it takes it (its own copy) until then. Taking P(m - 2) at frame
#: m lets dynamics of frame k + 2 wait for no more than perception of frame k, and perception publish P(k + 1) as
#: soon as dynamics of k + 2 has taken P(k); from three frames back, perception's next output would wait for a
#: dynamics frame that waits for perception to read the state of a later frame (a deadlock: every block holds one
#: frame; cosim.runtime.pipeline)
PERCEPTION_TAKEN_FRAMES_BACK = 2


def dynamics_reads(scenario) -> dict[str, int]:
    """Dynamics at frame m takes perception's P(m - min(1 + L, 2)) (only with perception feedback) and acts on
    P(m - 1 - L) from its copies (:data:`PERCEPTION_TAKEN_FRAMES_BACK`)."""
    if scenario.feedback != "perception" or "perception" not in scenario.participants:
        return {}
    return {"perception": min(1 + scenario.timing.latency_frames, PERCEPTION_TAKEN_FRAMES_BACK)}


def renderer_reads(scenario) -> dict[str, int]:
    """The renderer at frame m draws the dynamics state S(m)."""
    return {"dynamics": 0}


def perception_reads(scenario) -> dict[str, int]:
    """Perception at frame m reads the renderer's images I(m) and the dynamics state S(m) (the sensor's parent
    pose, and the truth on accuracy frames)."""
    return {"renderer": 0, "dynamics": 0} if "renderer" in scenario.participants else {"dynamics": 0}


#: where :func:`activity` writes: set by the process that runs a participant (cosim.runtime.child)
_activity_sink: Callable[[str], None] | None = None


def activity(text: str) -> None:
    """Say what this participant is doing while it starts ("compiling shaders"): the launcher's start-up report
    shows it while it waits, and names it if the start-up hangs. A no-op in-process."""
    if _activity_sink is not None:
        _activity_sink(text)


def set_activity(sink: Callable[[str], None] | None) -> None:
    """Install (or, with None, remove after clearing) the sink of :func:`activity`."""
    global _activity_sink
    if sink is None and _activity_sink is not None:
        _activity_sink("")
    _activity_sink = sink
