"""MCAP recording of a run: channels, point counts, image sizes, time stamps; killed runs; reading back.

Foxglove's channels are protobuf written by foxglove-sdk; tests/test_foxglove_messages.py checks the builders and decoders.
"""
from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from multiprocessing import shared_memory
from pathlib import Path

import numpy as np
import pytest
import test_viewer_standins as standins

from cosim.errors import ParticipantDied
from cosim.recording import RecordingError, RecordOptions, mcap_sink, read_recording
from cosim.recording.encode import heights_from_grid, image_from_msg, points_from_cloud
from cosim.runtime.launcher import launch

TOPICS = {"/tf": "foxglove.FrameTransform", "/dyn_state": "cosim.struct.dyn_state",
          "/render_state": "cosim.struct.render_state", "/perc_state": "cosim.struct.perc_state",
          "/cam0/rgb": "foxglove.CompressedImage", "/cam0/depth_encoded": "foxglove.RawImage",
          "/lidar/points": "foxglove.PointCloud", "/heightmap/truth": "foxglove.Grid",
          "/heightmap/perceived": "foxglove.Grid", "/cosim/frame": "cosim.Frame"}


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    out = tmp_path_factory.mktemp("rec") / "run"
    sc = standins.scenario(1.0)
    # flush every frame (the default batches up to 0.5 s per chunk), so that where a cut keeps whole frames
    # does not depend on how loaded the machine was while recording; images every frame (the default: every 5th)
    res = launch(sc, out, specs=standins.specs(), console_log=False,
                 sinks=[mcap_sink(RecordOptions(flush_s=0.0, image_every=1))])
    assert res.completed, res.error
    return sc, out, read_recording(out / "recording.mcap")


def test_channels_and_schemas(recorded):
    _, _, rec = recorded
    assert {t: c.schema for t, c in rec.channels.items()} == TOPICS
    assert all(c.encoding == ("protobuf" if c.schema.startswith("foxglove.") else "json")
               for c in rec.channels.values())
    assert rec.truncated is False


def test_every_frame_with_sim_time_stamps(recorded):
    sc, _, rec = recorded
    n = sc.frames + 1
    assert rec.frames == list(range(n))
    period_ns = round(sc.timing.sensor_period_s * 1e9)
    for topic in TOPICS:
        if topic == "/tf":
            continue
        msgs = rec.topic(topic)
        assert len(msgs) == n, topic
        for k, (log_time, m) in enumerate(msgs):
            assert log_time == k * period_ns
            assert m["timestamp"]["sec"] * 1_000_000_000 + m["timestamp"]["nsec"] == log_time


def test_point_counts_and_values(recorded):
    _, _, rec = recorded
    for k, (_, m) in enumerate(rec.topic("/lidar/points")):
        pts = points_from_cloud(m)
        assert len(pts) == int(standins.valid_beams(k).sum())
        want = standins.points(k)
        want = want[np.isfinite(want[:, 0])]
        np.testing.assert_array_equal(pts, want)


def test_image_sizes_and_lossless_depth(recorded):
    _, _, rec = recorded
    _, rgb = rec.topic("/cam0/rgb")[3]
    assert rgb["format"] == "jpeg" and image_from_msg(rgb).shape == (standins.IMG_H, standins.IMG_W, 3)
    for k, (_, depth) in enumerate(rec.topic("/cam0/depth_encoded")):
        assert (depth["encoding"], depth["width"], depth["height"], depth["step"]) == \
            ("rgba8", standins.IMG_W, standins.IMG_H, 4 * standins.IMG_W)
        assert depth["frame_id"] == "cam0"
        want = np.zeros((standins.IMG_H, standins.IMG_W, 4), np.uint8)
        want[..., :3] = (np.arange(standins.IMG_W)[None, :, None] + k) % 256
        want[..., 3] = 255
        assert depth["data"] == want.tobytes(), "depth-encoded bytes (alpha = validity included) must be lossless"
        np.testing.assert_array_equal(image_from_msg(depth), want)


def test_grids_and_transforms(recorded):
    sc, _, rec = recorded
    last = sc.frames
    _, g = rec.topic("/heightmap/truth")[-1]
    assert g["frame_id"] == "cart_grid" and g["column_count"] == standins.NX
    assert g["cell_size"]["x"] == pytest.approx(sc.cart.interior_length_m / standins.NX)
    np.testing.assert_array_equal(heights_from_grid(g), standins.truth(last))
    _, gp = rec.topic("/heightmap/perceived")[-1]
    assert np.isnan(heights_from_grid(gp)).any()
    tf = [m for _, m in rec.topic("/tf")]
    children = {m["child_frame_id"] for m in tf}
    assert children == {"combine", "tractor", "cart", "cart_grid", "lidar"}
    cart = [m for m in tf if m["child_frame_id"] == "cart"][-1]
    assert cart["translation"]["x"] == pytest.approx(2.0 * last * sc.timing.sensor_period_s - 6.0)
    q = cart["rotation"]
    assert q["z"] == pytest.approx(np.sin(0.01), abs=1e-9) and q["w"] == pytest.approx(np.cos(0.01), abs=1e-9)


def test_grids_every_frame_are_the_blocks(recorded):
    sc, _, rec = recorded
    truth, perceived = rec.topic("/heightmap/truth"), rec.topic("/heightmap/perceived")
    assert len(truth) == len(perceived) == sc.frames + 1
    for k, ((_, g), (_, gp)) in enumerate(zip(truth, perceived)):
        assert (g["row_stride"], g["cell_stride"], g["fields"][0]["type"]) == (4 * standins.NX, 4, 7)
        assert g["data"] == np.ascontiguousarray(standins.truth(k).T).tobytes()
        want = standins.truth(k)[::2, ::2]
        want[(np.arange(standins.NXC) + k) % 5 == 0, :] = np.nan
        np.testing.assert_array_equal(heights_from_grid(gp), want)


def test_foxglove_channels_parse_with_protobuf_from_the_files_own_schemas(recorded):
    """What Foxglove does: build the message type from the channel's schema record, parse each message."""
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
    from mcap.reader import make_reader

    _, out, rec = recorded
    classes, count = {}, {}
    with open(out / "recording.mcap", "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            if not schema.name.startswith("foxglove."):
                continue
            assert (schema.encoding, channel.message_encoding) == ("protobuf", "protobuf")
            if schema.name not in classes:
                pool = descriptor_pool.DescriptorPool()
                for fd in descriptor_pb2.FileDescriptorSet.FromString(schema.data).file:
                    pool.Add(fd)
                classes[schema.name] = message_factory.GetMessageClass(pool.FindMessageTypeByName(schema.name))
            m = classes[schema.name].FromString(message.data)
            k = count.get(channel.topic, 0)
            count[channel.topic] = k + 1
            ours = rec.topic(channel.topic)[k][1]
            assert m.timestamp.seconds * 10**9 + m.timestamp.nanos == message.log_time
            assert {"sec": m.timestamp.seconds, "nsec": m.timestamp.nanos} == ours["timestamp"]
            if schema.name == "foxglove.FrameTransform":
                assert (m.child_frame_id, m.translation.x, m.rotation.w) == \
                    (ours["child_frame_id"], ours["translation"]["x"], ours["rotation"]["w"])
            else:
                assert m.data == ours["data"] and m.frame_id == ours["frame_id"]
    assert set(count) == {t for t, s in TOPICS.items() if s.startswith("foxglove.")}
    assert count["/lidar/points"] == len(rec.frames)


def test_json_channels_validate_against_their_schemas(recorded):
    import jsonschema
    from mcap.reader import make_reader

    _, out, rec = recorded
    with open(out / "recording.mcap", "rb") as f:
        summary = make_reader(f).get_summary()
    json_channels = [c for c in summary.channels.values() if c.message_encoding == "json"]
    assert {c.topic for c in json_channels} == {"/dyn_state", "/render_state", "/perc_state", "/cosim/frame"}
    for c in json_channels:
        schema = summary.schemas[c.schema_id]
        assert schema.encoding == "jsonschema"
        validator = jsonschema.Draft202012Validator(json.loads(schema.data))
        for _, m in rec.topic(c.topic):
            validator.validate(m)
        assert set(json.loads(schema.data)["properties"]) >= set(rec.topic(c.topic)[0][1])


def test_scalars_match_timeseries_csv(recorded):
    _, out, rec = recorded
    rows = list(csv.DictReader((out / "timeseries.csv").open()))
    msgs = rec.topic("/dyn_state")
    assert len(rows) == len(msgs)
    for row, (_, m) in zip(rows, msgs):
        assert m["frame"] == int(row["frame"])
        assert m["desired_auger_x_m"] == float(row["dyn_state.desired_auger_x_m"])
        assert m["section3_fullness"] == float(row["dyn_state.section3_fullness"])
    assert msgs[0][1]["spilled_m3"] is None, "NaN is written as null (JSON has no NaN)"


def test_finished_file_has_an_index(recorded):
    from mcap.reader import make_reader

    _, out, rec = recorded
    with open(out / "recording.mcap", "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and summary.statistics.channel_count == len(TOPICS)
    assert summary.statistics.message_count == sum(len(v) for v in rec.messages.values())


def test_image_decimation(tmp_path, shm_clean):
    sc = standins.scenario(1.0)
    launch(sc, tmp_path / "run", specs=standins.specs(), console_log=False,
           sinks=[mcap_sink(RecordOptions(image_every=4, rgb_format="png"))])
    rec = read_recording(tmp_path / "run" / "recording.mcap")
    assert [m["timestamp"]["nsec"] // 100_000_000 + 10 * m["timestamp"]["sec"]
            for _, m in rec.topic("/cam0/rgb")] == list(range(0, sc.frames + 1, 4))
    assert len(rec.topic("/lidar/points")) == sc.frames + 1


def test_default_records_images_every_fifth_frame(tmp_path, shm_clean):
    sc = standins.scenario(1.0)
    launch(sc, tmp_path / "run", specs=standins.specs(), console_log=False, sinks=[mcap_sink()])
    rec = read_recording(tmp_path / "run" / "recording.mcap")
    assert RecordOptions().image_every == 5
    stamps = [m["timestamp"]["sec"] * 10**9 + m["timestamp"]["nsec"] for _, m in rec.topic("/cam0/depth_encoded")]
    assert stamps == [round(k * sc.timing.sensor_period_s * 1e9) for k in range(0, sc.frames + 1, 5)]
    assert len(rec.topic("/cam0/rgb")) == len(stamps) and len(rec.topic("/lidar/points")) == sc.frames + 1
    assert rec.metadata["recorder"]["frames"] == str(sc.frames + 1)
    assert float(rec.metadata["recorder"]["process_cpu_s"]) > 0


@pytest.mark.parametrize("compression", ["lz4", "none", "zstd"])
def test_raw_rgb_and_other_chunk_compressions_read_back(tmp_path, shm_clean, compression):
    sc = standins.scenario(0.5)
    launch(sc, tmp_path / "run", specs=standins.specs(), console_log=False,
           sinks=[mcap_sink(RecordOptions(image_every=1, rgb_format="raw", compression=compression, queue_frames=0))])
    rec = read_recording(tmp_path / "run" / "recording.mcap")
    assert rec.channels["/cam0/rgb"].schema == "foxglove.RawImage" and rec.frames == list(range(sc.frames + 1))
    for k, (_, m) in enumerate(rec.topic("/cam0/rgb")):
        img = image_from_msg(m)
        assert img.shape == (standins.IMG_H, standins.IMG_W, 4) and (img[..., 0] == k % 256).all()
        np.testing.assert_array_equal(img[:, 0, 1], np.arange(standins.IMG_H) * 4)
    from mcap.reader import make_reader

    with open(tmp_path / "run" / "recording.mcap", "rb") as f:
        summary = make_reader(f).get_summary()
    assert {c.compression for c in summary.chunk_indexes} == {"" if compression == "none" else compression}


def test_options_are_checked():
    with pytest.raises(ValueError, match="image_every must be >= 1"):
        RecordOptions(image_every=0)
    with pytest.raises(ValueError, match="jpeg_quality must be in 1..100"):
        RecordOptions(jpeg_quality=0)
    with pytest.raises(ValueError, match="rgb_format must be jpeg, png or raw"):
        RecordOptions(rgb_format="webp")
    with pytest.raises(ValueError, match="compression must be lz4, zstd or none"):
        RecordOptions(compression="gzip")
    with pytest.raises(ValueError, match="nice must be in 0..19"):
        RecordOptions(nice=-1)


def test_not_a_recording(tmp_path):
    bad = tmp_path / "x.mcap"
    bad.write_bytes(b"this is not an mcap file at all")
    with pytest.raises(RecordingError, match="not a readable MCAP recording"):
        read_recording(bad)


def test_child_killed_mid_run_leaves_a_finished_recording(tmp_path, shm_clean):
    res = launch(standins.scenario(2.0), tmp_path / "run", specs=standins.specs(perception={"kill_at": 6}),
                 console_log=False, sinks=[mcap_sink()])
    assert isinstance(res.error, ParticipantDied)
    rec = read_recording(tmp_path / "run" / "recording.mcap")
    assert rec.frames == list(range(6)) and rec.truncated is False
    assert len(rec.topic("/lidar/points")) == 6


KILL_SCRIPT = textwrap.dedent("""
    import sys
    sys.path.insert(0, {tests!r})
    import test_viewer_standins as standins
    from cosim.runtime.launcher import launch
    from cosim.recording import mcap_sink
    if __name__ == "__main__":
        launch(standins.scenario(600.0), {out!r}, specs=standins.specs(pace_s=0.005), console_log=False,
               sinks=[mcap_sink()])
""")


def _children(pid: int) -> dict[int, str]:
    """Child pid -> command line."""
    out = subprocess.run(["ps", "-ww", "-o", "pid=,args=", "--ppid", str(pid)], capture_output=True, text=True).stdout
    return {int(line.split()[0]): line for line in out.splitlines() if line.strip()}


def _gone(pids, timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if not any(Path(f"/proc/{p}").exists() and "Z" not in Path(f"/proc/{p}/stat").read_text().split()[2]
                   for p in pids):
            return True
        time.sleep(0.05)
    return False


def test_launcher_killed_mid_run_leaves_a_readable_recording(tmp_path):
    """SIGKILL of the launcher itself: its recorder sees the pipe close, writes every frame it was sent (each
    completed frame is sent as it completes) and finishes the file; every process of the run ends by itself."""
    out = tmp_path / "run"
    script = tmp_path / "run_it.py"
    script.write_text(KILL_SCRIPT.format(tests=str(Path(__file__).parent), out=str(out)))
    proc = subprocess.Popen([sys.executable, str(script)], cwd=Path(__file__).parent.parent)
    path = out / "recording.mcap"
    segment = None
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and (not path.exists() or path.stat().st_size < 60_000):
            time.sleep(0.1)
        assert path.exists(), "the run did not start recording"
        segment = json.loads((out / "run.json").read_text())["segment"]
        kids = _children(proc.pid)
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait(10)
    # ring children get SIGTERM from the kernel (PR_SET_PDEATHSIG), the recorder sees EOF, and the resource
    # tracker unlinks the dead launcher's semaphores and segment
    gone = _gone(kids, 15.0)
    for k in kids:
        if not gone:
            try:
                os.kill(k, signal.SIGKILL)  # only after the assertion below has failed: leave nothing behind
            except ProcessLookupError:
                pass
    assert gone, "processes of the killed run are still alive"
    try:
        shm = shared_memory.SharedMemory(segment)  # the dead launcher could not unlink it: clean up after it
        shm.close()
        shm.unlink()
    except FileNotFoundError:
        pass
    rec = read_recording(path)
    assert rec.truncated is False, "the recorder finishes the file after the launcher died"
    n = len(rec.frames)
    assert n >= 5 and rec.frames == list(range(n))
    every = RecordOptions().image_every  # the default decimates the camera images
    for topic in TOPICS:
        if topic != "/tf":
            want = len(range(0, n, every)) if TOPICS[topic].endswith("Image") else n
            assert len(rec.topic(topic)) == want, topic
    assert rec.topic("/cosim/frame")[-1][1]["frame"] == n - 1


@pytest.mark.parametrize("keep", [0.35, 0.6, 0.93])
def test_a_file_cut_off_mid_record_reads_up_to_its_last_whole_frame(recorded, tmp_path, keep):
    """What a power cut or a killed recorder leaves: the bytes up to some point, no summary."""
    sc, out, full = recorded
    data = (out / "recording.mcap").read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[:int(len(data) * keep)])
    rec = read_recording(cut)
    n = len(rec.frames)
    assert rec.truncated is True and 1 <= n <= sc.frames + 1
    assert rec.frames == list(range(n))
    for topic in TOPICS:
        if topic != "/tf":
            assert [m for _, m in rec.topic(topic)] == [m for _, m in full.topic(topic)[:n]], topic


LAG_BEAMS, LAG_H, LAG_W = 8, 4, 3


def _lag_schema():
    from shm_schema import ArrayBlock, Field, Schema, StructBlock, image_block

    return Schema([StructBlock("dyn_state", "dynamics", (Field("t_s", "s"), Field("cart_x_m", "m"),
                                                         Field("cart_y_m", "m"), Field("cart_yaw_rad", "rad"))),
                   ArrayBlock("heightmap_truth", "dynamics", "f4", (6, 3)),
                   image_block("cam0_depth", "renderer", LAG_H, LAG_W),
                   StructBlock("perc_state", "perception", (Field("t_s", "s"), Field("coverage"))),
                   ArrayBlock("lidar_points", "perception", "f4", (LAG_BEAMS, 4))],
                  ["dynamics", "renderer", "perception"])


def _lag_points(k: int) -> np.ndarray:
    pts = np.full((LAG_BEAMS, 4), float(k), np.float32)
    pts[:, 3] = np.arange(LAG_BEAMS)
    return pts


def _write_lagging(seg, k: int, current: bool = True, lagging: bool = True) -> None:
    """Frame ``k``'s current blocks (stamped k) and the lagging perception blocks of frame k - 1."""
    if current:
        with seg.write("dyn_state", k) as v:
            v.t_s, v.cart_x_m, v.cart_y_m, v.cart_yaw_rad = 0.1 * k, float(k), 0.0, 0.0
        with seg.write("heightmap_truth", k) as h:
            h[...] = k
        with seg.write("cam0_depth", k) as img:
            img[...] = k
    if lagging and k >= 1:
        with seg.write("perc_state", k - 1) as v:
            v.t_s, v.coverage = 0.1 * (k - 1), float(k - 1)
        with seg.write("lidar_points", k - 1) as p:
            p[...] = _lag_points(k - 1)


@pytest.mark.parametrize("queue_frames", [0, 2], ids=["synchronous", "frame-slots"])
def test_lagging_blocks_are_written_once_at_their_own_stamp(tmp_path, shm_clean, queue_frames):
    """Perception one frame behind: at sink call m its blocks hold frame m - 1 (their stamp); a last call
    m = last + 1 brings its final frame. Every message is logged at its block's stamp, none twice."""
    from cosim.recording import McapRecorder
    from shm_schema import Segment

    sc = standins.scenario(1.0)
    period_ns = round(sc.timing.sensor_period_s * 1e9)
    seg = Segment.local(_lag_schema())
    n = 7  # frames 0..6, then the extra call 7
    rec = McapRecorder(sc, tmp_path, seg, RecordOptions(image_every=2, queue_frames=queue_frames, flush_s=0.0))
    for m in range(n):
        _write_lagging(seg, m)
        rec(seg, m)
    _write_lagging(seg, n, current=False)
    rec(seg, n)
    rec.close()
    r = read_recording(tmp_path / "recording.mcap")
    assert r.frames == list(range(n + 1)) and r.truncated is False
    want = {"/dyn_state": range(n), "/heightmap/truth": range(n), "/cam0/depth_encoded": range(0, n, 2),
            "/perc_state": range(n), "/lidar/points": range(n)}
    for topic, stamps in want.items():
        times = [t for t, _ in r.topic(topic)]
        assert times == [k * period_ns for k in stamps], topic  # each stamp once, in order, at its own time
        for t, m in r.topic(topic):
            assert m["timestamp"]["sec"] * 10**9 + m["timestamp"]["nsec"] == t, topic
    for t, m in r.topic("/perc_state"):  # contents of the frame they are stamped with
        assert m["frame"] * period_ns == t and m["coverage"] == m["frame"]
    for t, m in r.topic("/lidar/points"):
        np.testing.assert_array_equal(points_from_cloud(m), _lag_points(t // period_ns))
    for t, m in r.topic("/heightmap/truth"):
        assert (heights_from_grid(m) == t // period_ns).all()
    tf = r.topic("/tf")
    cart = [(t, m) for t, m in tf if m["child_frame_id"] == "cart"]
    assert [t for t, _ in cart] == [k * period_ns for k in range(n)]
    assert all(m["translation"]["x"] == t // period_ns for t, m in cart)
    lidar_tf = [t for t, m in tf if m["child_frame_id"] == "lidar"]
    assert lidar_tf == [k * period_ns for k in range(n)], "constant transforms once per new time, none after the run"
    assert [t for t, _ in r.topic("/cosim/frame")] == [k * period_ns for k in range(n + 1)]


def test_frame_data_gives_each_blocks_stamp():
    from cosim.recording.writer import frame_data
    from shm_schema import Segment

    seg = Segment.local(_lag_schema())
    _write_lagging(seg, 3)
    structs, arrays, stamps = frame_data(seg, ("dyn_state", "perc_state", "lidar_points", "cam0_depth"))
    assert stamps == {"dyn_state": 3, "perc_state": 2, "lidar_points": 2, "cam0_depth": 3}
    assert structs["perc_state"]["coverage"] == 2.0 and set(arrays) == {"lidar_points", "cam0_depth"}
    assert np.shares_memory(arrays["lidar_points"], seg.view("lidar_points"))


def _lag_recorder(tmp_path, monkeypatch, queue_frames: int, notify_frames: int | None = None):
    """A recorder process fed from a local segment of the lagging schema; ``notify_frames`` None: the sink's own
    batching, else tell the recorder only every that many frames (and never on time)."""
    from cosim.recording import McapRecorder, sink
    from shm_schema import Segment

    if notify_frames is not None:
        monkeypatch.setattr(sink, "NOTIFY_S", 1e9)
    seg = Segment.local(_lag_schema())
    rec = McapRecorder(standins.scenario(1.0), tmp_path, seg, RecordOptions(queue_frames=queue_frames, flush_s=0.0))
    if notify_frames is not None:
        rec._notify_frames = notify_frames
    return seg, rec


def test_the_recorder_is_woken_once_per_batch_of_frames(tmp_path, shm_clean, monkeypatch):
    """Fast frames: one message per NOTIFY_FRAMES frames (plus the end), every frame in the file."""
    from cosim.recording.sink import NOTIFY_FRAMES

    seg, rec = _lag_recorder(tmp_path, monkeypatch, queue_frames=256, notify_frames=NOTIFY_FRAMES)
    n = 100
    for m in range(n):
        _write_lagging(seg, m)
        rec(seg, m)
    rec.close()
    r = read_recording(tmp_path / "recording.mcap")
    assert r.frames == list(range(n)) and rec.waits == 0
    assert int(r.metadata["recorder"]["wakeups"]) <= n // NOTIFY_FRAMES + 2


def test_frames_put_but_not_yet_told_are_recorded_when_the_launcher_is_gone(tmp_path, shm_clean, monkeypatch):
    """The pipe closes without an end mark (what a killed launcher leaves): the recorder takes every frame counted
    in the slots, told of or not, and finishes the file."""
    seg, rec = _lag_recorder(tmp_path, monkeypatch, queue_frames=16, notify_frames=1000)
    for m in range(6):
        _write_lagging(seg, m)
        rec(seg, m)
    assert rec._told == 0 and rec._slots.count == 6, "nothing told yet: the frames are only in the slots"
    rec._conn.close()  # the launcher is gone
    rec._proc.join(60)
    try:
        assert rec._proc.exitcode == 0
        r = read_recording(tmp_path / "recording.mcap")
        assert r.truncated is False and r.frames == list(range(6))
        assert [t for t, _ in r.topic("/dyn_state")] == [round(k * 0.1e9) for k in range(6)]
    finally:
        rec._closed = True
        rec._release_slots()


def test_a_full_set_of_slots_tells_the_recorder_before_the_ring_waits(tmp_path, shm_clean, monkeypatch):
    """Two slots and no batch ever due: the sink must tell the recorder of the full slots before it waits for a
    credit, or it would wait forever."""
    import threading

    seg, rec = _lag_recorder(tmp_path, monkeypatch, queue_frames=2, notify_frames=10**6)
    n = 12

    def feed():
        for m in range(n):
            _write_lagging(seg, m)
            rec(seg, m)

    t = threading.Thread(target=feed, daemon=True)
    t.start()
    t.join(60)
    assert not t.is_alive(), "the sink waited for a credit the recorder could never give back"
    rec.close()
    r = read_recording(tmp_path / "recording.mcap")
    assert r.frames == list(range(n)) and rec.waits >= 1 and not rec._failed
