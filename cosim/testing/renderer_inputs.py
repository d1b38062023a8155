"""The dynamics blocks a renderer participant reads, declared and written as the dynamics process does, for tests
and benchmarks that drive the renderer alone over an in-process segment (the names are docs/CONTRACTS.md's)."""
from __future__ import annotations

from typing import Mapping

import numpy as np

from shm_schema import ArrayBlock, Field, Segment, StructBlock

__all__ = ["STREAM_ROWS", "dynamics_blocks", "publish"]

#: rows of the grain stream block (points x (x, y, z, radius), m)
STREAM_ROWS = 64


def dynamics_blocks(state: Mapping[str, float], heights: np.ndarray) -> list:
    """``dyn_state`` (a field per key of ``state``; ``stream_points`` an integer), ``heightmap_truth`` of
    ``heights``' shape and ``stream`` (STREAM_ROWS, 4), all written by "dynamics"."""
    fields = tuple(Field(k, "", "i8" if k == "stream_points" else "f8") for k in state)
    return [StructBlock("dyn_state", "dynamics", fields), ArrayBlock("heightmap_truth", "dynamics", "f4", heights.shape),
            ArrayBlock("stream", "dynamics", "f4", (STREAM_ROWS, 4))]


def publish(seg: Segment, state: Mapping[str, float], heights: np.ndarray, stream: np.ndarray, frame: int) -> None:
    """Write one frame's dynamics blocks (as :func:`dynamics_blocks` declares them) into ``seg``."""
    with seg.write("dyn_state", frame) as v:
        v.update({k: int(x) if k == "stream_points" else x for k, x in state.items()})
    with seg.write("heightmap_truth", frame) as v:
        v[...] = heights
    with seg.write("stream", frame) as v:
        v[...] = stream
