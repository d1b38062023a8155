"""One frame's values of a run's segment as a read-only mapping (``cosim.Simulation.state``).

Keys are those of timeseries.csv (``"frame"``, ``"<block>.<field>"`` for every field of every struct block) plus
the name of every array block (``"heightmap_truth"``, ``"stream"``, ``"lidar_points"``, ...). Struct values are
Python floats/ints copied when the state was taken; array values are read-only views of the segment, so they
always show the run's latest frame (``np.array(state[name])`` keeps a copy).
"""
from __future__ import annotations

from collections.abc import Iterator, Mapping

import numpy as np

from shm_schema import Segment, StructBlock

__all__ = ["FrameState", "StateReader"]


class FrameState(Mapping):
    """The values after frame ``frame``. ``stamps`` maps each block to the frame its content belongs to: a
    deferred member (perception unless ``timing.schedule: sequential``) publishes frame m's outputs one turn late,
    so its blocks hold frame m - 1 until the run's last turn flushes them."""

    __slots__ = ("frame", "stamps", "_recs", "_index", "_arrays", "_keys")

    def __init__(self, frame: int, stamps: dict[str, int], recs: list[np.void], index: dict[str, tuple[int, str]],
                 arrays: dict[str, np.ndarray], keys: tuple[str, ...]):
        self.frame = frame
        self.stamps = stamps
        self._recs, self._index, self._arrays, self._keys = recs, index, arrays, keys

    def __getitem__(self, key: str):
        if key == "frame":
            return self.frame
        hit = self._index.get(key)
        if hit is not None:
            i, field = hit
            return self._recs[i][field].item()
        try:
            return self._arrays[key]
        except KeyError:
            raise KeyError(f"no value {key!r} in this run's state; keys look like 'dyn_state.t_s' or an array "
                           f"block's name ({', '.join(self._arrays)})") from None

    def __iter__(self) -> Iterator[str]:
        return iter(self._keys)

    def __len__(self) -> int:
        return len(self._keys)

    def __repr__(self) -> str:
        return f"<FrameState frame {self.frame}: {len(self._keys)} values>"


class StateReader:
    """Takes :class:`FrameState` snapshots of a segment: one memcpy per struct block, no array copies."""

    def __init__(self, seg: Segment):
        self._seg = seg
        self._structs = []
        self._arrays: dict[str, np.ndarray] = {}
        for b in seg.schema.blocks:
            if isinstance(b, StructBlock):
                self._structs.append((b.name, seg.view(b.name).array.reshape(1).view(np.uint8), b.dtype,
                                      tuple(f.name for f in b.fields)))
            else:
                ro = seg.view(b.name).view()
                ro.flags.writeable = False
                self._arrays[b.name] = ro
        #: "<block>.<field>" -> (index of the block's record, field)
        self._index = {f"{n}.{f}": (i, f) for i, (n, _, _, fields) in enumerate(self._structs) for f in fields}
        self._keys = ("frame", *self._index, *self._arrays)

    def take(self, frame: int) -> FrameState:
        """The segment's values now, as those of frame ``frame``."""
        seg = self._seg
        recs = [np.frombuffer(raw.tobytes(), dtype=dtype)[0] for _, raw, dtype, _ in self._structs]
        stamps = {b.name: seg.frame_of(b.name) for b in seg.schema.blocks}
        return FrameState(frame, stamps, recs, self._index, self._arrays, self._keys)
