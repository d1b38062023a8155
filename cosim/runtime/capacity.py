"""Will the run's shared memory fit? Checked before anything starts (the CLI exits 2 when it will not).

The segment (every block of the schema) lives in /dev/shm and in the machine's memory, and every child maps all of
it into its address space; an MCAP recording adds its frame slots (cosim.recording.sink.QUEUE_BYTES at most).
:func:`check_segment_fits` compares the total with /dev/shm's free space, the machine's available memory and the
address space a process may still map (``RLIMIT_AS``, ``ulimit -v``: cosim.scenario.memory.room) and refuses
with the largest blocks and their sizes, instead of a MemoryError, a failed mmap or a SIGBUS after start-up.
"""
from __future__ import annotations

from cosim.errors import RunRefused
from cosim.scenario.memory import UNLIMITED, Room, room, size_text
from shm_schema import Schema

__all__ = ["check_segment_fits", "SHOWN_BLOCKS"]

#: largest blocks named in a refusal
SHOWN_BLOCKS = 4


def check_segment_fits(schema: Schema, extra_bytes: int = 0, free: tuple | None = None) -> None:
    """Raise :class:`RunRefused` when ``schema``'s segment plus ``extra_bytes`` (other shared memory of the run)
    exceeds /dev/shm's free space, the available memory or the address space a process may map (``free``: a
    :class:`cosim.scenario.memory.Room` or (shm, memory[, address space]) bytes, default: measured)."""
    have = Room(*(free if free is not None else room()))
    need = schema.total_nbytes + extra_bytes
    if need <= min(have):
        return
    largest = sorted(schema.blocks, key=lambda b: -b.nbytes)[:SHOWN_BLOCKS]
    shown = ", ".join(f"{b.name} {'x'.join(map(str, getattr(b, 'shape', ()))) or 'struct'} {size_text(b.nbytes)}"
                      for b in largest)
    space = f", and a process has {size_text(have.address_space)} of address space for it (ulimit -v)" \
        if have.address_space < UNLIMITED else ""
    raise RunRefused(f"the run needs {size_text(need)} of shared memory, but /dev/shm has {size_text(have.shm)} "
                     f"free and the machine {size_text(have.memory)} available{space}; largest blocks: {shown}")
