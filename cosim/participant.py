"""The participant contract: one frame-stepped component of the ring (STYLE.md 4).

A participant is created from the scenario, started with the run's segment, then stepped once per frame in
ring order (dynamics -> renderer -> perception). The same object runs in-process (tests, debugging:
``cosim.lockstep.run_inprocess``) or inside an OS process over shared memory (``cosim.launcher``); it never
knows which. It must not synchronise, sleep or spin: the ring calls ``step`` when its turn comes.

Frame ids: frame 0 publishes the initial state (dynamics does not integrate); at frame m >= 1 dynamics
integrates t_{m-1} -> t_m and writes S(m), the renderer renders S(m) into I(m) and perception turns I(m) into
P(m). Feedback latency L (``timing.latency_frames``): at frame m dynamics acts on P(m - 1 - L), i.e. L frames
older than the freshest perception output (P(m-1)). Outputs for frames < 0 do not exist: "no measurement".

Each package exposes ``declare_blocks(scenario) -> list[Block]`` (``<pkg>/blocks.py``) and
``create(scenario) -> Participant`` (``<pkg>/participant.py``).
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Protocol, runtime_checkable

if TYPE_CHECKING:
    from shm_schema.segment import Segment

__all__ = ["Participant", "PARTICIPANTS"]

#: every participant name, in ring order
PARTICIPANTS: tuple[str, ...] = ("dynamics", "renderer", "perception")


@runtime_checkable
class Participant(Protocol):
    """One ring member. ``name`` is one of :data:`PARTICIPANTS` and the ``writer`` of its blocks."""

    name: str

    def start(self, segment: "Segment") -> None:
        """Bind views of the blocks it reads and writes; heavy set-up (GL context, tables) goes here."""

    def step(self, frame: int) -> None:
        """Do frame ``frame``: read inputs, compute, write outputs with ``segment.write(block, frame)``."""

    def close(self) -> None:
        """Release resources (GL context, files). Called once, also after a failure."""
