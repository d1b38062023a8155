"""Will the run's shared memory fit? Checked before anything starts (the CLI exits 2 when it will not).

The segment (every block of the schema) lives in /dev/shm and in the machine's memory; an MCAP recording adds
its frame slots (cosim.recording.sink.QUEUE_BYTES at most). :func:`check_segment_fits` compares the total with
/dev/shm's free space and the machine's available memory and refuses with the largest blocks and their sizes,
instead of a MemoryError or a SIGBUS minutes into the run.
"""
from __future__ import annotations

from cosim.errors import RunRefused
from cosim.scenario.plausibility import available_bytes, size_text
from shm_schema import Schema

__all__ = ["check_segment_fits", "SHOWN_BLOCKS"]

#: largest blocks named in a refusal
SHOWN_BLOCKS = 4


def check_segment_fits(schema: Schema, extra_bytes: int = 0, free: tuple[int, int] | None = None) -> None:
    """Raise :class:`RunRefused` when ``schema``'s segment plus ``extra_bytes`` (other shared memory of the run)
    exceeds /dev/shm's free space or the available memory (``free``: (shm, memory) bytes, default: measured)."""
    shm_free, mem_free = free or available_bytes()
    need = schema.total_nbytes + extra_bytes
    if need <= min(shm_free, mem_free):
        return
    largest = sorted(schema.blocks, key=lambda b: -b.nbytes)[:SHOWN_BLOCKS]
    shown = ", ".join(f"{b.name} {'x'.join(map(str, getattr(b, 'shape', ()))) or 'struct'} {size_text(b.nbytes)}"
                      for b in largest)
    raise RunRefused(f"the run needs {size_text(need)} of shared memory, but /dev/shm has {size_text(shm_free)} "
                     f"free and the machine {size_text(mem_free)} available; largest blocks: {shown}")
