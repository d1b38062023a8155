"""What the dashboard shows: one :class:`Snapshot` of a run, and the field discovery that fills its panels.

A snapshot is a plain copy (no shared memory in it): struct blocks as dicts, the images and arrays the panels
use, each block's frame stamp. Field names are discovered, not assumed: the time is a struct's ``t_s``, the
auger signals are ``desired_auger_x_m`` / ``actual_auger_x_m``, section fullness is ``section<k>_fullness``
(with a few spellings accepted); a run without them shows the panel as absent.
"""
from __future__ import annotations

import re
from collections import deque
from dataclasses import dataclass, field

import numpy as np

__all__ = ["Snapshot", "History", "find_field", "fullness", "auger_now", "sim_time", "wanted_block",
           "PREFERRED_STRUCT"]

#: struct searched first for the time, the auger signals and the fullness
PREFERRED_STRUCT = "dyn_state"
_FULLNESS = re.compile(r"^section_?(\d+)_(fullness|fill_fraction|fill)$")
_DESIRED = ("desired_auger_x_m", "auger_desired_x_m", "desired_auger_m")
_ACTUAL = ("actual_auger_x_m", "auger_actual_x_m", "auger_x_m", "actual_auger_m")
#: how many auger samples the dashboard's chart keeps
HISTORY_LEN = 600


def wanted_block(name: str, kind: str, shape: tuple[int, ...]) -> bool:
    """Whether the viewer copies block ``name``: structs, camera images, the LiDAR points, height maps, the
    camera sensors' measured depth and points (``cam_<name>_measured``, ``cam_<name>_points``)."""
    if kind == "struct" or kind == "image":
        return True
    return name == "lidar_points" or (len(shape) == 2 and (
        name.startswith("heightmap") or (name.startswith("cam_") and name.endswith(("_measured", "_points")))))


@dataclass
class Snapshot:
    """A consistent-per-block copy of a run at one moment.

    ``structs`` maps struct block -> {field: value}; ``images`` block -> (H, W, 4) uint8 (or (H, W, 3) in a
    replay); ``arrays`` block -> ndarray (``lidar_points`` and ``cam_<name>_points`` (N, 4) float32 in the
    sensor's camera axes, height maps (nx, ny) float32 m); ``frames`` block -> frame stamp of the copy (-1: never written).
    """

    frame: int = -1
    structs: dict[str, dict] = field(default_factory=dict)
    images: dict[str, np.ndarray] = field(default_factory=dict)
    arrays: dict[str, np.ndarray] = field(default_factory=dict)
    frames: dict[str, int] = field(default_factory=dict)
    #: block -> frame stamp now (a live source reads every block's stamp but copies big blocks only for panels)
    stamps: dict[str, int] = field(default_factory=dict)
    status: str = "waiting"
    rtf: float | None = None
    #: frames the viewer did not see between its last two snapshots (it may drop frames)
    dropped: int = 0

    @property
    def t_s(self) -> float | None:
        return sim_time(self.structs)

    @property
    def names(self) -> set[str]:
        """Every block this snapshot knows of, copied or not."""
        return set(self.stamps) | set(self.frames) | set(self.images) | set(self.arrays) | set(self.structs)

    def block_frame(self, name: str, stamp: bool = True) -> int | None:
        """Frame of block ``name``: its current stamp (``stamp``) or that of the copy held; None if unwritten."""
        f = self.stamps.get(name) if stamp else None
        if f is None:
            f = self.frames.get(name)
        return None if f is None or f < 0 else f


def _ordered(structs: dict[str, dict]):
    if PREFERRED_STRUCT in structs:
        yield PREFERRED_STRUCT, structs[PREFERRED_STRUCT]
    for k, v in structs.items():
        if k != PREFERRED_STRUCT:
            yield k, v


def find_field(structs: dict[str, dict], names) -> tuple[str, str] | None:
    """(block, field) of the first of ``names`` found, searching ``dyn_state`` first, or None."""
    for block, values in _ordered(structs):
        for n in names:
            if n in values:
                return block, n
    return None


def sim_time(structs: dict[str, dict]) -> float | None:
    hit = find_field(structs, ("t_s",))
    return None if hit is None else float(structs[hit[0]][hit[1]])


def fullness(structs: dict[str, dict]) -> tuple[str, list[float]] | None:
    """(block, fullness of sections 1..N) from the first struct with ``section<k>_fullness`` fields, or None."""
    for block, values in _ordered(structs):
        found = {}
        for name, v in values.items():
            m = _FULLNESS.match(name)
            if m:
                found[int(m.group(1))] = v
        if found:
            n = max(found)
            return block, [float(found.get(k, float("nan"))) for k in range(1, n + 1)]
    return None


def auger_now(structs: dict[str, dict]) -> tuple[str, float | None, float | None] | None:
    """(block, desired, actual) auger location (cart grid x, m), or None when neither field exists."""
    d, a = find_field(structs, _DESIRED), find_field(structs, _ACTUAL)
    if d is None and a is None:
        return None
    block = (d or a)[0]
    return (block, float(structs[d[0]][d[1]]) if d else None, float(structs[a[0]][a[1]]) if a else None)


class History:
    """The auger chart's recent samples: (t_s, desired, actual), one per distinct frame seen."""

    def __init__(self, maxlen: int = HISTORY_LEN):
        self._rows: deque = deque(maxlen=maxlen)
        self._last_frame = -1

    def add(self, snap: Snapshot) -> None:
        hit = auger_now(snap.structs)
        if hit is None:
            return
        frame = snap.block_frame(hit[0])
        if frame is None or frame == self._last_frame:
            return
        if frame < self._last_frame:
            self._rows.clear()
        self._last_frame = frame
        self._rows.append((snap.t_s, hit[1], hit[2]))

    def as_json(self) -> dict:
        t, d, a = (list(c) for c in zip(*self._rows)) if self._rows else ([], [], [])
        return {"t": t, "desired": d, "actual": a}
