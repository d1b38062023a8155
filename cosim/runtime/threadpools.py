"""Thread pools of the numerical libraries in a run's processes.

Every process of a run keeps numpy's BLAS (OpenBLAS), OpenMP, MKL and OpenCV single-threaded. The participants
multiply (N, 3) by (3, 3) matrices, where a second BLAS thread buys nothing, while an idle pool thread spins for a
while after each call and takes a core from llvmpipe's rasteriser or another participant. Measured on the 2-core
machine (default scenario, 30 s runs interleaved, bench/HISTORY.md 2026-11-24): the perception process's CPU fell
from 22 to 12 ms per frame and the run went from 4.5x to 6.5x real time. OpenCV's own pool (``parallel_for_``,
two threads on 2 cores) splits the rim search's small rasters (erode, connected components) and spent 0.5 ms of
CPU per frame to save no wall time (``python bench/run.py perception_replay``: cart 1.77 -> 1.23 ms CPU at the
same 1.24 ms wall, outputs bit-identical).

The libraries read these variables once, when they load, so they are set in the environment that children are
spawned with (and, by the command line, before anything imports numpy or cv2). A variable the user has set is left
as it is: ``OPENBLAS_NUM_THREADS=2 python launch.py`` still gets two BLAS threads.
"""
from __future__ import annotations

import os
from contextlib import contextmanager
from typing import Iterator

__all__ = ["POOL_VARIABLES", "single_threaded_pools", "default_to_single_threaded_pools"]

#: environment variables that size the thread pools of numpy's BLAS, of OpenMP code and of OpenCV
POOL_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENCV_FOR_THREADS_NUM")


def default_to_single_threaded_pools() -> list[str]:
    """Set every unset :data:`POOL_VARIABLES` to ``"1"`` in this process's environment; returns those set."""
    added = [v for v in POOL_VARIABLES if v not in os.environ]
    for v in added:
        os.environ[v] = "1"
    return added


@contextmanager
def single_threaded_pools() -> Iterator[None]:
    """Within the block, unset :data:`POOL_VARIABLES` read ``"1"`` (for processes started in it); restored after."""
    added = default_to_single_threaded_pools()
    try:
        yield
    finally:
        for v in added:
            os.environ.pop(v, None)
