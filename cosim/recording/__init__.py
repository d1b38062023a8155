"""MCAP recording of a run with Foxglove's well-known schemas, reading it back, and replaying it.

``launch(..., sinks=[mcap_sink()])`` (``launch.py run ... --record``) writes ``<run_dir>/recording.mcap`` with
Foxglove's well-known schemas in protobuf encoding: foxglove.PointCloud (LiDAR), foxglove.RawImage (depth-encoded
images, lossless) and CompressedImage (RGB), foxglove.Grid (height maps), foxglove.FrameTransform (vehicle and
sensor poses), plus one JSON scalar topic per struct block, so a run opens in Foxglove or Lichtblick without
ROS, written through foxglove-sdk's MCAP writer. The sink copies each completed frame into a shared-memory frame
slot; a recorder process encodes and writes (:mod:`.sink`, :mod:`.slots`, :mod:`.writer`; the messages: :mod:`cosim.foxglove.publish`). :func:`read_recording`
reads it back (also a file cut off by a killed run, up to its last completed frame);
:class:`cosim.viewer.replay.ReplaySource` serves it to the viewer's dashboard.
"""
from .reader import Channel, Recording, RecordingError, read_recording
from .sink import McapRecorder, mcap_sink
from .writer import DEFAULT_NAME, McapWriter, RecordOptions

__all__ = ["Channel", "Recording", "RecordingError", "read_recording", "DEFAULT_NAME", "McapRecorder",
           "McapWriter", "RecordOptions", "mcap_sink"]
