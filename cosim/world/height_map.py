"""Reading a terrain height-map file (``terrain.height_map_file``, docs/field.md) safely and within bounds.

A height map is a NumPy ``.npy`` file holding one 2-D array (nx, ny) of real heights, m. It is read in two steps,
so that nothing unbounded or unsafe is ever done with it:

1. :func:`height_map_header`: the file's size, magic string and header only (``numpy.lib.format``): the format
   version, a numeric real dtype (no objects, so no pickles are ever loaded), two dimensions of at least 2 samples
   and at most :data:`MAX_TERRAIN_CELLS` cells, and a file exactly as long as the header says;
2. :func:`read_height_map`: then the array with ``allow_pickle=False``, every height finite and within
   :data:`MAX_HEIGHT_M` of zero.

Every refusal is a :class:`HeightMapError` whose message says what the file holds and what is wanted (the
scenario loader reports it at ``terrain.height_map_file``).
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from cosim.scenario.config.terrain import MAX_TERRAIN_CELLS

__all__ = ["HeightMapError", "MAX_TERRAIN_CELLS", "MAX_HEIGHT_M", "height_map_header", "read_height_map"]

#: largest |height| of a height map, m: the length limit of every other key (cosim.scenario.config.limits); the
#: highest fields are about 5 km above the sea, and a map is best given relative to the field
MAX_HEIGHT_M = 1e4
#: longest .npy header read, bytes (numpy writes 64-4096)
_MAX_HEADER_BYTES = 1 << 16


class HeightMapError(ValueError):
    """A height-map file that cannot be the ground: the message says what it holds and what is wanted."""


def _what_it_is(head: bytes) -> str:
    """A short description of a file that is not a .npy array, from its first bytes."""
    if not head:
        return "an empty file"
    if head[:2] == b"PK":
        return "a zip archive (an .npz holds several arrays: save the one height map with numpy.save)"
    if head[:1] == b"\x80":
        return "pickled data (save the heights with numpy.save as a plain numeric array)"
    try:
        head.decode("utf-8")
        return "a text file (save the heights with numpy.save, not as text)"
    except UnicodeDecodeError:
        return "not a .npy file"


def height_map_header(path: str | os.PathLike) -> tuple[tuple[int, int], np.dtype]:
    """The (shape, dtype) of the height map in ``path``, read from its header alone; raises HeightMapError for a
    file that is not a bounded 2-D real array of at least 2 x 2 samples."""
    path = Path(path)
    try:
        size = path.stat().st_size
        with path.open("rb") as f:
            head = f.read(len(np.lib.format.MAGIC_PREFIX) + 2)
            if not head.startswith(np.lib.format.MAGIC_PREFIX):
                raise HeightMapError(f"the file is {_what_it_is(head)}, not a NumPy .npy array of heights")
            f.seek(0)
            readers = {(1, 0): np.lib.format.read_array_header_1_0, (2, 0): np.lib.format.read_array_header_2_0}
            try:
                version = np.lib.format.read_magic(f)
                if version not in readers:
                    raise EOFError(f"format version {version} is not one numpy.save writes")
                shape, _, dtype = readers[version](f, max_header_size=_MAX_HEADER_BYTES)
            except (ValueError, EOFError, SyntaxError) as exc:
                raise HeightMapError(f"the .npy header cannot be read ({exc}); the file is truncated or "
                                     "damaged") from None
            offset = f.tell()
    except OSError as exc:
        raise HeightMapError(f"cannot read the file: {exc.strerror or exc}") from None
    if dtype.hasobject or dtype.kind not in "fiu" or dtype.fields is not None:
        raise HeightMapError(f"the array holds {dtype} values; a height map holds real numbers (float or int)")
    if len(shape) != 2 or min(shape) < 2:
        raise HeightMapError(f"the array's shape is {shape}; a height map is 2-D (nx, ny), at least 2 x 2")
    cells = shape[0] * shape[1]
    if cells > MAX_TERRAIN_CELLS:
        raise HeightMapError(f"{shape[0]:,} x {shape[1]:,} = {cells:,} samples; at most {MAX_TERRAIN_CELLS:,} "
                             "(2048 x 2048) fit: use a coarser cell_m")
    if size != offset + cells * dtype.itemsize:
        raise HeightMapError(f"the file is {size:,} bytes but its header promises {offset + cells * dtype.itemsize:,}"
                             " (a truncated or damaged file)")
    return (int(shape[0]), int(shape[1])), dtype


def read_height_map(path: str | os.PathLike) -> np.ndarray:
    """The heights (nx, ny) float64 m of the height map in ``path``, checked (module docstring); raises
    HeightMapError."""
    height_map_header(path)
    try:
        heights = np.load(Path(path), allow_pickle=False).astype(np.float64)
    except (OSError, ValueError, EOFError) as exc:
        raise HeightMapError(f"the array cannot be read ({exc})") from None
    if not np.all(np.isfinite(heights)):
        bad = int(np.count_nonzero(~np.isfinite(heights)))
        raise HeightMapError(f"{bad:,} of its {heights.size:,} heights are not finite (NaN or infinity)")
    peak = float(np.max(np.abs(heights)))
    if peak > MAX_HEIGHT_M:
        raise HeightMapError(f"a height of {peak:g} m is beyond {MAX_HEIGHT_M:g} m; give the heights in metres, "
                             "relative to the field")
    return heights
