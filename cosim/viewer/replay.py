"""Replay: serve a recording to the live viewer's dashboard (``python -m cosim.viewer --replay FILE.mcap``).

:class:`ReplaySource` has the viewer source interface (``name``, ``frames_planned``, ``history``,
``snapshot()``, ``check_end()``, ``close()``) and plays the recorded frames back at ``speed`` times the
simulation's pace, holding the last frame at the end (or looping). :meth:`ReplaySource.control` pauses, plays,
steps and seeks (the dashboard's replay bar; ``POST /api/replay``), :meth:`ReplaySource.position` says where
the replay is. Topics map back to block names: ``/<block>``
(cosim.struct) -> struct block, ``/<cam>/rgb`` -> ``<cam>_rgb`` ((H, W, 3) from a CompressedImage, (H, W, 4)
from a RawImage), ``/<cam>/depth_encoded`` -> ``<cam>_depth`` ((H, W, 4) uint8, the block's bytes),
``/lidar/points`` -> ``lidar_points`` (camera axes again), ``/heightmap/<kind>`` -> ``heightmap_<kind>``; a
camera sensor's ``/cam_<name>/depth`` -> ``cam_<name>_measured``, ``/depth_exact`` -> ``cam_<name>_depth``,
``/labels`` -> ``cam_<name>_labels``, ``/points`` -> ``cam_<name>_points`` (arrays), ``/right`` ->
``cam_<name>_right`` (an image).
"""
from __future__ import annotations

import bisect
import threading
import time
from pathlib import Path

from cosim.foxglove.cameras import CAMERA_ARRAY_PARTS
from cosim.recording.encode import heights_from_grid, image_from_msg, points_from_cloud
from cosim.recording.reader import RecordingError, read_recording
from cosim.viewer.viewinfo import METADATA_NAME, ViewInfo

__all__ = ["ReplaySource", "block_of_topic", "REPLAY_ACTIONS"]

#: what :meth:`ReplaySource.control` accepts
REPLAY_ACTIONS = ("play", "pause", "step", "seek")

#: how many auger samples the replayed chart shows
HISTORY_LEN = 600


def block_of_topic(topic: str, schema: str) -> tuple[str, str] | None:
    """(block name, kind) a recorded topic stands for, kind in struct|image|array; None for others."""
    parts = topic.strip("/").split("/")
    if schema.startswith("cosim.struct."):
        return schema[len("cosim.struct."):], "struct"
    if len(parts) == 2 and parts[0].startswith("cam_"):
        arrays = {suffix: part for part, suffix in CAMERA_ARRAY_PARTS.items()}
        if parts[1] in arrays and schema in ("foxglove.RawImage", "foxglove.PointCloud"):
            return f"{parts[0]}_{arrays[parts[1]]}", "array"
    if schema in ("foxglove.CompressedImage", "foxglove.RawImage") and len(parts) == 2:
        return f"{parts[0]}_{'depth' if parts[1] == 'depth_encoded' else parts[1]}", "image"
    if schema == "foxglove.PointCloud" and topic == "/lidar/points":
        return "lidar_points", "array"
    if schema == "foxglove.Grid" and len(parts) == 2 and parts[0] == "heightmap":
        return f"heightmap_{parts[1]}", "array"
    return None


class _ReplayHistory:
    """The auger chart's samples up to the replayed frame."""

    def __init__(self, owner: "ReplaySource"):
        self._owner = owner

    def as_json(self) -> dict:
        o = self._owner
        i = o._index + 1
        rows = o._auger[max(0, i - HISTORY_LEN):i]
        t, d, a = (list(c) for c in zip(*rows)) if rows else ([], [], [])
        return {"t": t, "desired": d, "actual": a}


class ReplaySource:
    """Plays a recording back as viewer snapshots."""

    def __init__(self, path: Path | str, speed: float = 1.0, loop: bool = False):
        from cosim.viewer.snapshot import auger_now

        if speed <= 0:
            raise ValueError(f"replay speed must be > 0, got {speed}")
        self.rec = read_recording(path)
        if not self.rec.frames:
            raise RecordingError(f"{path} holds no completed frame to replay")
        self.name = f"replay of {Path(path).name}"
        self.frames = self.rec.frames
        self.frames_planned = self.frames[-1]
        period = self.rec.metadata.get("run", {}).get("sensor_period_s")
        self.period_s = float(period) if period else 0.1
        self.speed, self.loop = float(speed), bool(loop)
        self._topics: dict[str, tuple[str, str, list[int], list[dict]]] = {}
        for topic, ch in self.rec.channels.items():
            hit = block_of_topic(topic, ch.schema)
            if hit is None or topic not in self.rec.messages:
                continue
            msgs = self.rec.messages[topic]
            frames = [m.get("frame", round(t / 1e9 / self.period_s)) for t, m in msgs]
            self._topics[topic] = (hit[0], hit[1], frames, [m for _, m in msgs])
        self._decoded: dict[str, tuple[int, object]] = {}
        self._lock = threading.Lock()
        #: the replay clock: frame index ``_base`` at monotonic time ``_t0``, advancing while ``_playing``
        self._t0 = time.monotonic()
        self._base = 0.0
        self._playing = True
        self._index = 0
        self._auger = []
        for k in range(len(self.frames)):
            structs = self._structs_at(self.frames[k])[0]
            hit = auger_now(structs)
            if hit is not None:
                t = structs.get(hit[0], {}).get("t_s", self.frames[k] * self.period_s)
                self._auger.append((t, hit[1], hit[2]))
        self.history = _ReplayHistory(self)
        #: the run's cart, sensors and fill target: the recording's ``view`` metadata, else the scenario.yaml of
        #: the run directory the recording lies in (None: unknown)
        self.view = self._view(Path(path))
        self.size_m = self.view.size_m if self.view is not None else self._grid_size_m()

    def _view(self, path: Path) -> ViewInfo | None:
        record = self.rec.metadata.get(METADATA_NAME, {}).get("json")
        if record:
            try:
                return ViewInfo.from_json(record)
            except ValueError:
                pass
        return ViewInfo.from_scenario_yaml(path.parent / "scenario.yaml")

    def _grid_size_m(self) -> tuple[float, float] | None:
        """(length, width) the recorded truth height map covers, m (its cell size times its cells), or None."""
        for topic in ("/heightmap/truth", "/heightmap/perceived"):
            msgs = self.rec.messages.get(topic)
            if not msgs:
                continue
            msg = msgs[0][1]
            try:
                nx = int(msg["column_count"])
                ny = len(msg["data"]) // 4 // nx
                cell = msg["cell_size"]
                return nx * float(cell["x"]), ny * float(cell["y"])
            except (KeyError, TypeError, ValueError, ZeroDivisionError):
                return None
        return None

    def _latest(self, topic: str, frame: int) -> tuple[int, dict] | None:
        _, _, frames, msgs = self._topics[topic]
        i = bisect.bisect_right(frames, frame) - 1
        return (frames[i], msgs[i]) if i >= 0 else None

    def _structs_at(self, frame: int) -> tuple[dict, dict]:
        structs, stamps = {}, {}
        for topic, (block, kind, _, _) in self._topics.items():
            if kind != "struct":
                continue
            hit = self._latest(topic, frame)
            if hit is not None:
                stamps[block] = hit[0]
                structs[block] = {k: (float("nan") if v is None else v) for k, v in hit[1].items()
                                  if k not in ("timestamp", "frame")}
        return structs, stamps

    def _decode(self, topic: str, kind_block: str, frame: int, msg: dict):
        cached = self._decoded.get(topic)
        if cached is not None and cached[0] == frame:
            return cached[1]
        if self.rec.channels[topic].schema in ("foxglove.CompressedImage", "foxglove.RawImage"):
            data = image_from_msg(msg)
        elif kind_block == "lidar_points" or kind_block.endswith("_points"):
            data = points_from_cloud(msg)
        else:
            data = heights_from_grid(msg)
        self._decoded[topic] = (frame, data)
        return data

    def _position(self, now: float) -> float:
        """Frame index (fractional) of the replay clock at monotonic time ``now``."""
        pos = self._base + ((now - self._t0) * self.speed / self.period_s if self._playing else 0.0)
        n = len(self.frames)
        return pos % n if self.loop else min(pos, n - 1)

    def _current_index(self) -> int:
        return int(self._position(time.monotonic()))

    def control(self, action: str, value: float | None = None) -> dict:
        """Drive the replay: ``play``, ``pause``, ``step`` (``value`` frames, default 1, negative back; pauses)
        or ``seek`` (to recorded frame number ``value``, the nearest recorded one at or before it; keeps playing
        or paused). Returns :meth:`position`. Raises ValueError for another action or a missing seek target."""
        with self._lock:
            now = time.monotonic()
            pos = self._position(now)
            n = len(self.frames)
            if action == "play":
                if not self.loop and int(pos) >= n - 1:
                    pos = 0.0  # play at the end starts over
                self._playing = True
            elif action == "pause":
                self._playing = False
            elif action == "step":
                self._playing = False
                pos = min(max(int(pos) + int(1 if value is None else value), 0), n - 1)
            elif action == "seek":
                if value is None:
                    raise ValueError("seek needs a frame number")
                pos = float(max(bisect.bisect_right(self.frames, int(value)) - 1, 0))
            else:
                raise ValueError(f"unknown replay action {action!r}; one of {REPLAY_ACTIONS}")
            self._base, self._t0 = float(int(pos)) if action != "play" else pos, now
            self._index = int(self._position(now))
        return self.position()

    def position(self) -> dict:
        """{playing, frame (recorded frame number shown), index, first, last, count, speed} of the replay."""
        i = self._current_index()
        return {"playing": self._playing, "frame": self.frames[i], "index": i, "first": self.frames[0],
                "last": self.frames[-1], "count": len(self.frames), "speed": self.speed}

    def snapshot(self, big: bool = True):
        """The snapshot of the frame the replay clock has reached (``big`` is accepted for the source interface:
        a replay always decodes what the frame shows, once per frame and topic)."""
        from cosim.viewer.snapshot import Snapshot

        with self._lock:
            self._index = self._current_index()
            frame = self.frames[self._index]
            structs, stamps = self._structs_at(frame)
            snap = Snapshot(frame=frame, structs=structs, frames=dict(stamps))
            for topic, (block, kind, _, _) in self._topics.items():
                if kind == "struct":
                    continue
                hit = self._latest(topic, frame)
                if hit is None:
                    continue
                data = self._decode(topic, block, hit[0], hit[1])
                (snap.images if kind == "image" else snap.arrays)[block] = data
                snap.frames[block] = hit[0]
            at_end = not self.loop and self._index == len(self.frames) - 1
            snap.status = "replay ended" if at_end else ("replay" if self._playing else "replay paused")
            snap.rtf = None if at_end or not self._playing else self.speed
            return snap

    def check_end(self) -> bool:
        return False

    def close(self) -> None:
        self._decoded.clear()
