"""The live Foxglove server, checked by a real WebSocket client (the ``websockets`` package).

The client speaks the Foxglove WebSocket protocol as the app does: subprotocol ``foxglove.sdk.v1`` (the SDK's
name for ``foxglove.websocket.v1``), reads ``serverInfo`` and ``advertise``, subscribes, and parses the binary
message frames (opcode 1, subscription id, log time, payload) with the protobuf package from the schema each
channel advertises (a base64 FileDescriptorSet). A sink holds the run at one frame while the client reads, so
the values are compared with the blocks of a known frame; a run with the server leaves the same timeseries as
one without it.
"""
from __future__ import annotations

import asyncio
import base64
import json
import struct
import time
from pathlib import Path

import numpy as np
import pytest
import test_viewer_standins as standins

from cosim.runtime.launcher import ObserverSpec, launch

websockets = pytest.importorskip("websockets", reason="the test client needs the websockets package ([test] extra)")
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory  # noqa: E402

SUBPROTOCOL = "foxglove.sdk.v1"
STARTUP_S = 60.0
#: how long the client waits for a message of every topic it asked for, s
RECEIVE_S = 30.0
INTERVAL_S = 0.05


def message_class(name: str, schema_b64: str):
    """Protobuf class ``name`` from an advertised schema (base64 FileDescriptorSet)."""
    pool = descriptor_pool.DescriptorPool()
    for fd in descriptor_pb2.FileDescriptorSet.FromString(base64.b64decode(schema_b64)).file:
        pool.Add(fd)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(name))


async def _client(port: int, topics: set[str], first_frame: int, period_ns: int) -> tuple[dict, dict]:
    """(advertised {topic: channel}, {topic: (log_time, payload)} of the first message of each of ``topics``
    at frame ``first_frame`` or later)."""
    async with websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=[SUBPROTOCOL], max_size=None,
                                  open_timeout=10) as ws:
        assert ws.subprotocol == SUBPROTOCOL
        info = json.loads(await ws.recv())
        assert info["op"] == "serverInfo" and info["name"].startswith("graincosim")
        channels: dict[str, dict] = {}
        while not topics <= set(channels):
            msg = json.loads(await asyncio.wait_for(ws.recv(), RECEIVE_S))
            if msg["op"] == "advertise":
                channels.update({c["topic"]: c for c in msg["channels"]})
        ids = {c["id"]: t for t, c in channels.items() if t in topics}
        await ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": i, "channelId": i} for i in ids]}))
        got: dict[str, tuple[int, bytes]] = {}
        deadline = time.monotonic() + RECEIVE_S
        while set(got) != topics and time.monotonic() < deadline:
            frame = await asyncio.wait_for(ws.recv(), RECEIVE_S)
            if isinstance(frame, bytes) and frame[0] == 1:
                _, sub, log_time = struct.unpack_from("<BIQ", frame)
                if log_time >= first_frame * period_ns:
                    got.setdefault(ids[sub], (log_time, frame[13:]))
        return channels, got


class ClientAt:
    """Sink factory: at frame ``at`` wait for the server's announce file, then read ``topics`` with the client
    while the run holds that frame."""

    def __init__(self, at: int, announce: Path, topics: set[str], period_s: float):
        self.at, self.announce, self.topics, self.period_ns = at, announce, topics, round(period_s * 1e9)
        self.channels, self.got, self.blocks = {}, {}, {}

    def __call__(self, scenario, run_dir, segment):
        def sink(seg, frame):
            if frame != self.at:
                return
            deadline = time.monotonic() + STARTUP_S
            while not self.announce.exists():
                assert time.monotonic() < deadline, "the Foxglove server did not announce itself"
                time.sleep(0.05)
            port = json.loads(self.announce.read_text())["port"]
            self.blocks = {n: (seg.frame_of(n), seg.snapshot(n)[1]) for n in (b.name for b in seg.schema.blocks)}
            self.channels, self.got = asyncio.run(_client(port, self.topics, 0, self.period_ns))
        return sink


def observer(sc, announce: Path) -> ObserverSpec:
    return ObserverSpec("foxglove", "cosim.foxglove.live:observe",
                        {"port": 0, "scenario_json": sc.model_dump_json(), "announce": str(announce),
                         "interval_s": INTERVAL_S})


def decode(client: ClientAt, topic: str):
    ch = client.channels[topic]
    log_time, payload = client.got[topic]
    return log_time, message_class(ch["schemaName"], ch["schema"]).FromString(payload)


STANDIN_TOPICS = {"/lidar/points": "foxglove.PointCloud", "/cam0/depth_encoded": "foxglove.RawImage",
                  "/cam0/rgb": "foxglove.CompressedImage", "/heightmap/truth": "foxglove.Grid",
                  "/heightmap/perceived": "foxglove.Grid", "/tf": "foxglove.FrameTransform",
                  "/dyn_state": "cosim.struct.dyn_state"}


def test_a_client_receives_every_topic_and_the_run_is_unchanged(tmp_path, shm_clean):
    sc = standins.scenario(2.0)
    base = tmp_path / "base"
    assert launch(sc, base, specs=standins.specs(), console_log=False).completed
    client = ClientAt(6, tmp_path / "fox.json", set(STANDIN_TOPICS), sc.timing.sensor_period_s)
    res = launch(sc, tmp_path / "run", specs=standins.specs(), console_log=False,
                 observers=[observer(sc, tmp_path / "fox.json")], sinks=[client])
    assert res.completed, res.error
    assert (tmp_path / "run" / "timeseries.csv").read_bytes() == (base / "timeseries.csv").read_bytes()
    for topic, schema in STANDIN_TOPICS.items():
        ch = client.channels[topic]
        assert ch["schemaName"] == schema, topic
        assert ch["encoding"] == ("json" if schema.startswith("cosim.") else "protobuf")
    assert set(client.got) == set(STANDIN_TOPICS), "a message of every subscribed topic"
    period_ns = round(sc.timing.sensor_period_s * 1e9)

    def frame_of(log_time: int) -> int:
        assert log_time % period_ns == 0
        return log_time // period_ns

    t, cloud = decode(client, "/lidar/points")
    k = frame_of(t)
    assert (cloud.frame_id, cloud.point_stride, [f.name for f in cloud.fields]) == ("lidar", 16, ["x", "y", "z", "range"])
    want = standins.points(k)
    want = want[np.isfinite(want[:, 0])]
    mount = np.frombuffer(cloud.data, "<f4").reshape(-1, 4)
    # lidar frame = mount frame, body axes: (x, y, z) = (Z, -X, Y) of the camera-axes block
    np.testing.assert_array_equal(mount, np.column_stack([want[:, 2], -want[:, 0], want[:, 1], want[:, 3]]))
    t, depth = decode(client, "/cam0/depth_encoded")
    k = frame_of(t)
    assert (depth.encoding, depth.width, depth.height, depth.step) == ("rgba8", standins.IMG_W, standins.IMG_H,
                                                                      4 * standins.IMG_W)
    img = np.frombuffer(depth.data, np.uint8).reshape(standins.IMG_H, standins.IMG_W, 4)
    np.testing.assert_array_equal(img[0, :, 0], (np.arange(standins.IMG_W) + k) % 256)
    assert (img[..., 3] == 255).all()
    t, rgb = decode(client, "/cam0/rgb")
    assert rgb.format == "jpeg" and rgb.data[:2] == b"\xff\xd8"
    t, grid = decode(client, "/heightmap/truth")
    assert (grid.frame_id, grid.column_count, grid.cell_stride) == ("cart_grid", standins.NX, 4)
    np.testing.assert_array_equal(np.frombuffer(grid.data, "<f4").reshape(standins.NY, standins.NX).T,
                                  standins.truth(frame_of(t)))
    t, tf = decode(client, "/tf")
    assert tf.timestamp.seconds * 10**9 + tf.timestamp.nanos == t
    t, dyn = client.got["/dyn_state"]
    dyn = json.loads(dyn)
    assert dyn["frame"] == frame_of(t) and dyn["cart_x_m"] == pytest.approx(2.0 * dyn["t_s"] - 6.0)


def test_the_scene_of_a_real_run(tmp_path, shm_clean):
    from cosim.foxglove.scene import ENTITIES
    from cosim.scenario.loader import load_scenario, resolve_scenario_arg
    from cosim.world.scene import scene_from_state

    sc = load_scenario(resolve_scenario_arg("default"), ["duration_s=3"],
                       extra={"renderer": "none", "feedback": "ground_truth"})
    announce = tmp_path / "fox.json"
    client = ClientAt(10, announce, {"/scene", "/tf"}, sc.timing.sensor_period_s)
    res = launch(sc, tmp_path / "run", console_log=False, observers=[observer(sc, announce)], sinks=[client])
    assert res.completed, res.error
    t, update = decode(client, "/scene")
    k = t // round(sc.timing.sensor_period_s * 1e9)
    assert k == client.blocks["dyn_state"][0] == client.at, "the held frame's scene"
    scene = scene_from_state(sc, client.blocks["dyn_state"][1], client.blocks["heightmap_truth"][1],
                             client.blocks["stream"][1])
    by_id = {e.id: e for e in update.entities}
    assert tuple(by_id) == ENTITIES
    cubes = [c for e in update.entities for c in e.cubes]
    assert len(cubes) == len(scene.boxes)
    for cube, w, half in zip(cubes, scene.boxes.world_from_box, scene.boxes.half_extents):
        p, q = cube.pose.position, cube.pose.orientation
        np.testing.assert_allclose([p.x, p.y, p.z], w[:3, 3], atol=1e-9)
        np.testing.assert_allclose(rotation(q), w[:3, :3], atol=1e-9)
        np.testing.assert_allclose([cube.size.x, cube.size.y, cube.size.z], 2 * half, atol=1e-12)
    cyls = [c for e in update.entities for c in e.cylinders]
    assert len(cyls) == len(scene.cylinders) and len(by_id["auger"].cylinders) == 1
    for cyl, p0, p1 in zip(cyls, scene.cylinders.p0, scene.cylinders.p1):
        c = cyl.pose.position
        np.testing.assert_allclose([c.x, c.y, c.z], (p0 + p1) / 2, atol=1e-9)
        # the cylinder's axis is its z: the rotation takes z onto p1 - p0
        np.testing.assert_allclose(rotation(cyl.pose.orientation) @ [0, 0, 1], (p1 - p0) / np.linalg.norm(p1 - p0),
                                   atol=1e-9)
        assert cyl.size.z == pytest.approx(np.linalg.norm(p1 - p0))
    grain = by_id["grain"]
    assert grain.frame_id == "cart_grid"
    h = client.blocks["heightmap_truth"][1]
    tri = grain.triangles[0]
    assert len(tri.points) == (h.shape[0] + 2) * (h.shape[1] + 2) and len(tri.indices) % 3 == 0
    assert max(p.z for p in tri.points) == pytest.approx(float(np.nanmax(h)), abs=1e-6)


def rotation(q) -> np.ndarray:
    """3 x 3 rotation matrix of a unit quaternion message."""
    x, y, z, w = q.x, q.y, q.z, q.w
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def test_a_busy_port_stops_the_run_before_it_starts(tmp_path, capsys):
    import socket

    from cosim.cli import main

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        code = main(["run", "default", "--foxglove", "--foxglove-port", str(port), "--out", str(tmp_path / "run"),
                     "--quiet"])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert err == (f"--foxglove-port {port}: 127.0.0.1:{port} is already in use; choose another port "
                   "(nothing was started)")
    assert not (tmp_path / "run").exists()


def test_run_extras_adds_the_observer():
    from cosim.cli import build_parser, run_extras
    from cosim.scenario.config import Scenario

    sc = Scenario(format_version=1, duration_s=1.0)
    observers, sinks = run_extras(build_parser().parse_args(["run", "--foxglove", "--foxglove-port", "0"]), sc)
    assert sinks == [] and [(o.name, o.target, o.kwargs["port"]) for o in observers] == \
        [("foxglove", "cosim.foxglove.live:observe", 0)]
    assert Scenario.model_validate_json(observers[0].kwargs["scenario_json"]) == sc


def _layout_topics(node, out: set[str]) -> set[str]:
    """Topics a layout names: 3D topic settings, image topics and the topic part of plot paths."""
    if isinstance(node, dict):
        for k, v in node.items():
            if k == "topics" and isinstance(v, dict):
                out.update(v)
            elif k == "imageTopic":
                out.add(v)
            elif k == "value" and isinstance(v, str) and v.startswith("/"):
                out.add(v.split(".")[0])
            _layout_topics(v, out)
    elif isinstance(node, list):
        for v in node:
            _layout_topics(v, out)
    return out


def test_the_shipped_layout_is_built_from_the_sdk_and_names_the_runs_topics_and_fields():
    import foxglove

    from cosim.foxglove import LAYOUT
    from cosim.foxglove.layout import layout_json
    from cosim.foxglove.live import SCENE_TOPIC
    from cosim.foxglove.publish import FramePublisher, RunInfo
    from cosim.runtime.specs import build_schema, ring_specs
    from cosim.scenario.loader import load_scenario, resolve_scenario_arg
    from shm_schema import StructBlock

    assert LAYOUT.read_text() == layout_json(), "regenerate with python -m cosim.foxglove.layout --out " + str(LAYOUT)
    layout = json.loads(LAYOUT.read_text())
    sc = load_scenario(resolve_scenario_arg("default"), [])
    schema = build_schema(sc, ring_specs(sc))
    topics = set(FramePublisher(RunInfo.of(sc), schema, foxglove.Context()).topics) | {SCENE_TOPIC}
    assert {"/lidar/points", "/heightmap/truth", "/beams/depth_encoded", "/dyn_state"} <= topics
    named = _layout_topics(layout, set())
    assert named and named <= topics, named - topics
    fields = {f"/{b.name}.{f.name}" for b in schema.blocks if isinstance(b, StructBlock) for f in b.fields}
    paths = {v for v in json.dumps(layout).replace('"', " ").split() if v.startswith("/") and "." in v}
    assert paths and paths <= fields, paths - fields


def test_the_dashboard_and_foxglove_ports_must_differ():
    from cosim.cli import build_parser, run_extras
    from cosim.scenario.config import Scenario

    args = build_parser().parse_args(["run", "--viewer", "--foxglove", "--foxglove-port", "9123", "--viewer-port",
                                      "9123"])
    with pytest.raises(ValueError, match=r"--foxglove-port 9123 is the dashboard's port too"):
        run_extras(args, Scenario(format_version=1, duration_s=1.0))
    assert build_parser().parse_args(["run"]).foxglove_port != build_parser().parse_args(["run"]).viewer_port


def test_the_layout_command_writes_the_shipped_file(tmp_path):
    from cosim.foxglove import LAYOUT
    from cosim.foxglove.layout import main

    assert main(["--out", str(tmp_path / "layout.json")]) == 0
    assert (tmp_path / "layout.json").read_text() == LAYOUT.read_text()
