"""The participant contract: one frame-stepped component of the ring.

A participant is created from the scenario, started with the run's segment, then stepped once per frame in
ring order (dynamics -> renderer -> perception). The same object runs in-process (tests, debugging:
``cosim.runtime.lockstep.run_inprocess``) or inside an OS process over shared memory (``cosim.runtime.launcher``); it never
knows which. It must not synchronise, sleep or spin: the ring calls ``step`` when its turn comes.

Frame ids: frame 0 publishes the initial state (dynamics does not integrate); at frame m >= 1 dynamics
integrates t_{m-1} -> t_m and writes S(m), the renderer renders S(m) into I(m) and perception turns I(m) into
P(m). Feedback latency L (``timing.latency_frames``): at frame m dynamics acts on P(m - 1 - L), i.e. L frames
older than the freshest perception output (P(m-1)). Outputs for frames < 0 do not exist: "no measurement".

Overlap (``timing.overlap_perception``, :func:`perception_overlaps`): when dynamics does not need P(m) before
frame m + 2, perception splits its frame. ``step(m)`` first publishes P(m - 1), kept from its previous turn,
then gathers what it needs from I(m) and returns the rest of its work as a callable; the ring passes the token
on and then runs that callable, which computes P(m) into private memory while dynamics and the renderer do
frame m + 1. So at the supervisor's turn of frame m the perception blocks hold P(m - 1) (their stamps say so)
and a last turn, after frame N, runs only ``flush()`` (publish P(N)) and the supervisor. Every block is read
and written at the same point of the token order in a process ring and in-process, so the results are
identical, and identical to the serial ring.

Each package exposes ``declare_blocks(scenario) -> list[Block]`` (``<pkg>/blocks.py``) and
``create(scenario) -> Participant`` (``<pkg>/participant.py``).
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Callable, Protocol, runtime_checkable

if TYPE_CHECKING:
    from shm_schema.segment import Segment

__all__ = ["Participant", "PARTICIPANTS", "perception_overlaps"]

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
    return bool(t.overlap_perception) and (scenario.feedback != "perception" or t.latency_frames >= 1)
