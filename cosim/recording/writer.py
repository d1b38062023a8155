"""The MCAP writer: a :class:`~cosim.foxglove.publish.FramePublisher` whose context's sink is an MCAP file.

The file is written by foxglove-sdk's MCAP writer (``foxglove.open_mcap`` on a context of its own) with
Foxglove's schemas in protobuf encoding and our own JSON channels; the topics are those of
:mod:`cosim.foxglove.publish`. Camera images are recorded every ``image_every``-th frame (the sink passes them
on their beat), everything else every frame. Chunks are compressed (zstd by default) and have no size limit:
the writer closes its chunk and flushes the file every ``flush_s`` seconds (1 s; 0: after each frame), so zstd
finds each frame's repeats of the one before, and a file cut off at any point reads up to its last whole frame
flushed. The SDK's writer is told not to seek (``disable_seeking``): a chunk reaches the file whole, never as a
header waiting for its length. :func:`frame_data` takes a frame's blocks from a segment (the synchronous path)
and :meth:`cosim.recording.slots.FrameSlots.frame` from a frame slot.
"""
from __future__ import annotations

import errno
import logging
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Literal, NamedTuple

import foxglove
import numpy as np
from foxglove.mcap import MCAPCompression, MCAPWriteOptions

from cosim.foxglove.publish import FRAME_TOPIC, VEHICLES, FramePublisher, Recorded, RunInfo
from cosim.viewer.viewinfo import METADATA_NAME as VIEW_METADATA
from shm_schema import Schema, Segment, StructBlock

__all__ = ["RecordOptions", "RunInfo", "McapWriter", "Recorded", "FrameData", "frame_data", "DEFAULT_NAME", "PROFILE",
           "VEHICLES", "FRAME_TOPIC"]

log = logging.getLogger("cosim.recording")

#: file name of a run's recording inside its run directory
DEFAULT_NAME = "recording.mcap"
#: MCAP profile string of our files
PROFILE = "graincosim"
_COMPRESSION = {"zstd": MCAPCompression.Zstd, "lz4": MCAPCompression.Lz4, "none": None}


@dataclass(frozen=True)
class RecordOptions:
    """What and how to record. ``path`` None: ``<run_dir>/recording.mcap``."""

    path: Path | None = None
    #: record camera images every this many frames (1: every frame; 5: 2 Hz at the default 0.1 s frames); every
    #: other topic is recorded every frame. Images are ~80 % of a default frame's bytes (2 x 1.3 MB raw depth)
    image_every: int = 5
    #: RGB camera images (``<cam>_rgb``, present when the viewer asked for them): JPEG or PNG CompressedImage, or
    #: a RawImage rgba8 (no encoding work, larger); depth-encoded images are always RawImage (lossless)
    rgb_format: Literal["jpeg", "png", "raw"] = "jpeg"
    jpeg_quality: int = 90
    #: chunk compression (foxglove-sdk's MCAP writer, default level): zstd shrinks raw depth-encoded images and
    #: the LiDAR points repeated from an earlier frame of the chunk; lz4 is faster and larger; none writes raw
    compression: Literal["lz4", "zstd", "none"] = "zstd"
    #: frame slots in flight to the recorder process (0: no process, write synchronously inside the sink; None:
    #: as many as fit in QUEUE_BYTES, within MIN_SLOTS..MAX_SLOTS: ~20 for a default frame, 256 for small ones)
    queue_frames: int | None = None
    #: the recorder process closes a chunk and flushes at most this often, s (0: after every frame): 1 s (10
    #: default frames, ~11 MB before compression) lets zstd find each frame's repeats of the one before (the
    #: first frame of a chunk has none) and the second image pair's repeats of the first; ~30 % less CPU time
    #: and file than 0.5 s
    flush_s: float = 1.0
    #: niceness added to the recorder process: it yields the CPU to the ring (the credits still guarantee that
    #: it gets every frame: when all slots are full the ring waits for it). Not SCHED_IDLE: on a machine whose
    #: other work keeps both cores busy an idle-class recorder gets next to no CPU, the slots fill and the ring
    #: waits on it for as long as that work lasts (measured: 30-92x real time against 67-120x at nice 10 in the
    #: same rounds), and an unprivileged process can never leave SCHED_IDLE again
    nice: int = 10

    def __post_init__(self) -> None:
        if not 0 <= self.nice <= 19:
            raise ValueError(f"nice must be in 0..19, got {self.nice}")
        if self.flush_s < 0:
            raise ValueError(f"flush_s must be >= 0, got {self.flush_s}")
        if self.queue_frames is not None and self.queue_frames < 0:
            raise ValueError(f"queue_frames must be >= 0, got {self.queue_frames}")
        if self.image_every < 1:
            raise ValueError(f"image_every must be >= 1, got {self.image_every}")
        if not 1 <= self.jpeg_quality <= 100:
            raise ValueError(f"jpeg_quality must be in 1..100, got {self.jpeg_quality}")
        if self.rgb_format not in ("jpeg", "png", "raw"):
            raise ValueError(f"rgb_format must be jpeg, png or raw, got {self.rgb_format!r}")
        if self.compression not in ("lz4", "zstd", "none"):
            raise ValueError(f"compression must be lz4, zstd or none, got {self.compression!r}")


class FrameData(NamedTuple):
    """One sink call's recorded blocks for :meth:`McapWriter.write`: ``structs`` {block: {field: value}},
    ``arrays`` {block: array} (views, valid while the source is quiescent) and ``stamps`` {block: the frame its
    contents belong to} for every block in either."""

    structs: dict[str, dict]
    arrays: dict[str, np.ndarray]
    stamps: dict[str, int]


#: the SDK's logger of a sink's failed writes (it logs each failed message as a warning instead of raising)
SDK_SINK_LOGGER = "foxglove.log_sink_set"
#: causes the SDK's I/O error text names, as errno values (os error N in its text is taken as errno N)
#: free space below which a write error that names no cause is taken for a full disk, bytes
FULL_BYTES = 2**20
_KINDS = {"StorageFull": errno.ENOSPC, "QuotaExceeded": errno.EDQUOT, "PermissionDenied": errno.EACCES,
          "ReadOnlyFilesystem": errno.EROFS}


class _WriteErrors(logging.Handler):
    """Keeps the first failed-write message the SDK logs (and drops the rest: one per message after a failure)."""

    def __init__(self):
        super().__init__(logging.WARNING)
        self.first: str | None = None

    def emit(self, record) -> None:
        if self.first is None:
            self.first = record.getMessage()


def _os_error(text: str, path: Path) -> OSError:
    """The OSError an SDK write error's text describes (ENOSPC for a full disk; EIO when it names none)."""
    code = next((c for kind, c in _KINDS.items() if kind in text), None)
    if code is None and "code: " in text:
        digits = text.split("code: ", 1)[1].split(",", 1)[0].strip()
        code = int(digits) if digits.isdigit() else None
    if code is None:  # an error inside the SDK's compression stream names no cause: a full disk is the usual one
        try:
            st = os.statvfs(Path(path).parent)
            code = errno.ENOSPC if st.f_bavail * st.f_frsize < FULL_BYTES else None
        except OSError:
            pass
    code = code or errno.EIO
    return OSError(code, os.strerror(code) if code != errno.EIO else text, str(path))


class McapWriter(FramePublisher):
    """Writes one run's frames to an MCAP file (see the module docstring for the channels).

    ``run`` is a :class:`RunInfo` (or a scenario, turned into one); ``schema`` is the run's segment schema;
    ``run_id`` and ``fingerprint`` go into the file's ``run`` metadata record, and what the dashboard's replay
    needs of the scenario into its ``view`` record (cosim.viewer.viewinfo).
    """

    def __init__(self, run, schema: Schema, path: Path, options: RecordOptions, run_id: str = "",
                 fingerprint: str = "", flush_s: float = 0.0):
        self.options = options
        self.flush_s = float(flush_s)
        self._t_flush = time.monotonic()
        self._dirty = False
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        run = run if isinstance(run, RunInfo) else RunInfo.of(run)
        self.frames_written = 0
        self._closed = False
        # the SDK logs a failed write instead of raising it: keep the first, raise it as an OSError (_check)
        self._errors = _WriteErrors()
        sdk_log = logging.getLogger(SDK_SINK_LOGGER)
        sdk_log.addHandler(self._errors)
        sdk_log.propagate = False
        ctx = foxglove.Context()
        self._mcap = foxglove.open_mcap(self.path, allow_overwrite=True, context=ctx, writer_options=MCAPWriteOptions(
            compression=_COMPRESSION[options.compression], profile=PROFILE, chunk_size=None, compression_threads=0,
            disable_seeking=True))
        super().__init__(run, schema, ctx, options.rgb_format, options.jpeg_quality)
        self._mcap.write_metadata("run", {"run_id": run_id, "fingerprint": fingerprint, "scenario": self._run.scenario,
                                          "sensor_period_s": repr(self.period_s)})
        if run.view_json:                         # the dashboard's replay: cart, sensors, fill target (docs/viewer.md)
            self._mcap.write_metadata(VIEW_METADATA, {"json": run.view_json})
        self._mcap.flush()

    def write(self, frame: int, structs: dict[str, dict], arrays: dict[str, np.ndarray],
              stamps: dict[str, int] | None = None) -> None:
        """Write sink call ``frame`` (:meth:`FramePublisher.publish`), then flush if ``flush_s`` has passed."""
        self.publish(frame, structs, arrays, stamps)
        self._check()
        self.frames_written += 1
        self._dirty = True
        if time.monotonic() - self._t_flush >= self.flush_s:
            self.flush()

    def _check(self) -> None:
        """Raise the first write the SDK reported failed, as an OSError naming the file."""
        if self._errors.first is not None:
            raise _os_error(self._errors.first, self.path)

    def _sdk(self, call, *args) -> None:
        """``call(*args)`` on the SDK's writer, its failure raised as an OSError naming the file."""
        try:
            call(*args)
        except RuntimeError as exc:
            raise _os_error(self._errors.first or str(exc), self.path) from None
        self._check()

    def flush_due_in(self) -> float | None:
        """Seconds until a flush is due (0: now), None when nothing is waiting to be flushed."""
        if not self._dirty:
            return None
        return max(0.0, self.flush_s - (time.monotonic() - self._t_flush))

    def flush(self) -> None:
        """Close the chunk and flush the file now, if any frame was written since the last flush."""
        if self._dirty:
            self._t_flush = time.monotonic()
            self._dirty = False
            self._sdk(self._mcap.flush)

    def close(self, stats: dict[str, str] | None = None) -> None:
        """Write ``stats`` (if given) as the ``recorder`` metadata record, the summary, and close the file.
        Idempotent."""
        if self._closed:
            return
        self._closed = True
        if self._errors.first is None:
            if stats:
                self._sdk(self._mcap.write_metadata, "recorder", {"frames": str(self.frames_written), **stats})
            self._sdk(self._mcap.close)
        logging.getLogger(SDK_SINK_LOGGER).removeHandler(self._errors)
        log.info("recording %s: %d frames", self.path, self.frames_written)


def frame_data(seg: Segment, names) -> FrameData:
    """(structs, arrays, stamps) of blocks ``names`` of ``seg`` for :meth:`McapWriter.write`: struct fields copied
    into dicts, arrays as zero-copy views (valid while the blocks are quiescent: the supervisor holds the token,
    or they are a frame slot the recorder owns), and each block's stamp (``seg.frame_of``: the frame its
    contents belong to, which may be earlier than the sink call's). Blocks never written are left out."""
    structs, arrays, stamps = {}, {}, {}
    for n in names:
        s = seg.frame_of(n)
        if s < 0:
            continue
        stamps[n] = s
        v = seg.view(n)
        if isinstance(seg.schema.block(n), StructBlock):
            arr = v.array
            structs[n] = dict(zip(arr.dtype.names, arr.item()))
        else:
            arrays[n] = v
    return FrameData(structs, arrays, stamps)
