"""What memory a run may have, and whether the beam pattern fits it: checked before anything starts.

Three limits, each measured here (:func:`room`):

* ``shm``: free bytes of /dev/shm, where the run's segment lives;
* ``memory``: the machine's available memory (MemAvailable);
* ``address_space``: the address space a process of the run has for the segment and its arrays: the soft
  ``RLIMIT_AS`` (``ulimit -v``, inherited by the children) less what a child maps of its own (the interpreter,
  numpy, OpenCV, the renderer's libraries and threads: :data:`CHILD_MAPPED_BYTES`, or this process's VmSize when
  that is larger). Every child maps the whole segment into its address space.

A figure that cannot be read (no /proc, no limit) is a large number, never the reason for a refusal.
:func:`memory_problems` compares a beam pattern's memory with them (the launcher compares the whole segment:
cosim.runtime.capacity).
"""
from __future__ import annotations

import os
import resource
from pathlib import Path
from typing import NamedTuple

from cosim.scenario.config import Scenario

__all__ = ["Room", "room", "size_text", "memory_problems", "SHARED_BYTES_PER_BEAM", "PROCESS_BYTES_PER_BEAM",
           "SHM_DIR", "UNLIMITED", "CHILD_MAPPED_BYTES"]

#: shared memory per beam, bytes: the ``lidar_points`` block, (N, 4) float32
SHARED_BYTES_PER_BEAM = 16
#: process memory per beam, at least, bytes: each of renderer and perception holds the beam table (2 float64)
#: and the unit directions (3 float64) = 40 B, plus perception's points (16 B) and ranges (8 B)
PROCESS_BYTES_PER_BEAM = 2 * 40 + 24
SHM_DIR = "/dev/shm"
#: stands for a figure that cannot be read, or a limit that is not set, bytes
UNLIMITED = 1 << 62
#: address space a child maps besides the segment, bytes: measured VmPeak 0.27 GB (dynamics), 0.82 GB
#: (perception, OpenCV) and 0.87 GB (renderer, llvmpipe GL and its threads) on the default scenario
CHILD_MAPPED_BYTES = 1 << 30


class Room(NamedTuple):
    """Bytes a run may use: free /dev/shm, available memory, address space one more process may map."""

    shm: int
    memory: int
    address_space: int = UNLIMITED


def _meminfo(path: str, key: str) -> int:
    """The ``key:`` line of a /proc file, in bytes (the files give kB); UNLIMITED when it cannot be read."""
    try:
        for line in Path(path).read_text().splitlines():
            if line.startswith(key + ":"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return UNLIMITED


def room() -> Room:
    """The three limits, measured now (see the module docstring)."""
    try:
        st = os.statvfs(SHM_DIR)
        shm = st.f_bavail * st.f_frsize
    except OSError:
        shm = UNLIMITED
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    space = UNLIMITED
    if soft != resource.RLIM_INFINITY:
        own = _meminfo("/proc/self/status", "VmSize")
        space = max(0, soft - max(CHILD_MAPPED_BYTES, own if own != UNLIMITED else 0))
    return Room(shm, _meminfo("/proc/meminfo", "MemAvailable"), space)


def size_text(n: float) -> str:
    """``n`` bytes for a message: "614.4 KiB"."""
    for unit in ("B", "KiB", "MiB", "GiB", "TiB"):
        if n < 1024 or unit == "TiB":
            return f"{n:.1f} {unit}" if unit != "B" else f"{int(n)} B"
        n /= 1024
    return f"{n:.1f} TiB"


def memory_problems(s: Scenario, free: tuple | None = None, beams: int | None = None) -> list[tuple[tuple, str]]:
    """The beam pattern's memory against /dev/shm's free space, the machine's available memory and the address
    space a process may map (``free``: a :class:`Room` or (shm, memory[, address space]) bytes, default:
    measured). ``beams``: the pattern's beam count (a CSV table's rows); default: the grid's."""
    if s.lidar is None:
        return []                                 # cameras only: their blocks are checked with the segment's size
    p = s.lidar.pattern
    if beams is None:
        if p.preset == "csv":
            return []
        beams = p.azimuth_count * p.elevation_count
    have = Room(*(free if free is not None else room()))
    shared, private = beams * SHARED_BYTES_PER_BEAM, beams * PROCESS_BYTES_PER_BEAM
    if shared <= have.shm and shared + private <= have.memory and shared + private <= have.address_space:
        return []
    shape = f"{p.azimuth_count} x {p.elevation_count} = " if p.preset != "csv" else ""
    limit = f" and a process {size_text(have.address_space)} of address space for them (ulimit -v)" \
        if have.address_space < UNLIMITED else ""
    where = ("sensor",) if not s.sensors else ("sensors", s.lidar_name)
    return [(where + ("pattern",),
             f"{shape}{beams:,} beams need at least {size_text(shared)} of shared memory (block lidar_points) and "
             f"{size_text(private)} in the processes, but {SHM_DIR} has {size_text(have.shm)} free, the machine "
             f"{size_text(have.memory)} available{limit}; "
             + ("lower azimuth_count or elevation_count" if p.preset != "csv" else "use a smaller beam table"))]
