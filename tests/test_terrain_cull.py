"""The terrain's triangles no beam can meet, left out before the beam-native GL renderer draws them
(renderer_proc/gl/meshcull.py): every beam lies inside the pattern's planes, a triangle left out is one no beam
meets (the exact ray cast against each triangle alone), and the image drawn with the cull is the image drawn with
every triangle, byte for byte, from the packaged rough_terrain scenario's LiDAR and from poses around it."""
from __future__ import annotations

import numpy as np
import pytest

from cosim.scenario.config.sensing import Pattern
from cosim.scenario.loader import load_scenario, packaged_scenarios
from cosim.world.beamtarget import beam_layout
from cosim.world.geometry import make_transform
from cosim.world.scene import Scene, scene_from_state
from dynamics_proc.model import ModelParams, initial_world, signals
from renderer_proc.gl.meshcull import pattern_planes, visible_faces
from renderer_proc.projection import world_from_sensor


def _rough_scene():
    """The packaged rough_terrain scenario's first frame: (scenario, scene, world_from_sensor)."""
    s = load_scenario(packaged_scenarios()["rough_terrain"])
    p = ModelParams.from_scenario(s)
    world = initial_world(s, p)
    state = signals(world, p)
    state["stream_points"] = 0
    scene = scene_from_state(s, state, np.asarray(world.heights, np.float32), np.zeros((64, 4)))
    return s, scene, world_from_sensor(s, state)


def _turned(pose: np.ndarray, yaw_deg: float, pitch_deg: float) -> np.ndarray:
    """``pose`` turned about the world's z by ``yaw_deg`` and about its own x by ``pitch_deg``."""
    y, p = np.radians(yaw_deg), np.radians(pitch_deg)
    rz = np.array([[np.cos(y), -np.sin(y), 0.0], [np.sin(y), np.cos(y), 0.0], [0.0, 0.0, 1.0]])
    rx = np.array([[1.0, 0.0, 0.0], [0.0, np.cos(p), -np.sin(p)], [0.0, np.sin(p), np.cos(p)]])
    return make_transform(rz @ pose[:3, :3] @ rx, pose[:3, 3])


def _hit_triangles(points: np.ndarray, faces: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Whether each triangle (points (V, 3) sensor frame) is met by one of the beams ``d`` (N, 3), float64
    Moller-Trumbore with a barycentric slack of 1e-6 (the fragment shader's and more)."""
    v0, v1, v2 = (points[faces[:, k]] for k in range(3))
    e1, e2 = v1 - v0, v2 - v0
    met = np.zeros(len(faces), bool)
    for chunk in np.array_split(np.arange(len(d)), 16):
        dd = d[chunk][:, None, :]
        pv = np.cross(dd, e2[None])
        det = np.einsum("nfj,fj->nf", pv, e1)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            u = np.einsum("fj,nfj->nf", -v0, pv) * inv
            qv = np.cross(-v0, e1)
            v = np.einsum("nj,fj->nf", d[chunk], qv) * inv
            t = np.einsum("fj,fj->f", e2, qv)[None] * inv
        eps = 1e-6
        met |= ((det != 0) & (u >= -eps) & (v >= -eps) & (u + v <= 1 + eps) & (t > 0)).any(axis=0)
    return met


def test_every_beam_lies_inside_the_patterns_planes():
    for pattern in (Pattern(preset="honeycomb"), Pattern(preset="grid", azimuth_min_deg=-70, azimuth_max_deg=20,
                                                          elevation_min_deg=-80, elevation_max_deg=-10)):
        lay = beam_layout(pattern)
        normals, floor = pattern_planes(lay.direction_image())
        d = lay.directions / np.linalg.norm(lay.directions, axis=1)[:, None]
        assert np.all(d @ normals.T >= floor - 1e-7)           # every beam (the float32 image's, to its round-off)
        assert floor.max() > -1e-7                              # and a side at least is tight on the beams
    honeycomb = pattern_planes(beam_layout(Pattern(preset="honeycomb")).direction_image())[1]
    assert np.all(np.abs(honeycomb) < 1e-7)                     # a field about its centre: all four sides tight
    whole = beam_layout(Pattern(preset="grid", azimuth_min_deg=-180, azimuth_max_deg=179, elevation_min_deg=-30,
                                elevation_max_deg=10))
    _, floor = pattern_planes(whole.direction_image())
    assert floor.min() < -0.5                                   # a full turn: the side planes never cull


@pytest.mark.parametrize("yaw,pitch", [(0.0, 0.0), (90.0, 20.0), (200.0, -30.0)])
def test_a_triangle_left_out_is_met_by_no_beam(yaw, pitch):
    s, scene, pose = _rough_scene()
    mesh = scene.meshes[-1]
    pose = _turned(pose, yaw, pitch)
    lay = beam_layout(s.lidar.pattern)
    sensor_from_mesh = np.linalg.inv(pose) @ mesh.world_from_mesh
    points = mesh.vertices @ sensor_from_mesh[:3, :3].T + sensor_from_mesh[:3, 3]
    kept = visible_faces(points, mesh.faces, *pattern_planes(lay.direction_image()))
    assert 0 < len(kept) < 0.6 * len(mesh.faces)                # most of the patch lies outside the field
    keep = set(map(tuple, kept.tolist()))
    gone = np.array([tuple(f) not in keep for f in mesh.faces.tolist()])
    assert np.array_equal(mesh.faces[~gone], kept)              # a subset, in the mesh's order
    d = lay.directions[::9] / np.linalg.norm(lay.directions[::9], axis=1)[:, None]
    assert not _hit_triangles(points, mesh.faces[gone], d).any()
    assert _hit_triangles(points, kept, d).sum() > 100          # and the field does see ground


@pytest.mark.gl
def test_the_culled_terrain_draws_the_same_bytes(ctx):
    from renderer_proc.gl.beam import GLBeamRenderer

    s, scene, pose = _rough_scene()
    lay = beam_layout(s.lidar.pattern)
    ground_only = Scene(scene.boxes, scene.cylinders, scene.heightfield, scene.meshes[-1:], None, scene.poses)
    images = {}
    for cull in (True, False):
        r = GLBeamRenderer(lay, s.lidar.codec, context=ctx, rgb=True, cull_terrain=cull)
        for k, (sc, p) in enumerate([(scene, pose), (ground_only, _turned(pose, 90.0, 20.0)),
                                     (scene, _turned(pose, 170.0, -25.0)), (scene, pose)]):
            enc, rgb = np.zeros(lay.shape + (4,), np.uint8), np.zeros(lay.shape + (4,), np.uint8)
            r.set_scene(sc)
            r.draw(0, p)
            r.read_depth(0, enc)
            r.read_rgb(0, rgb)
            images[cull, k] = (enc, rgb)
        r.close()
    for k in range(4):
        for a, b in zip(images[True, k], images[False, k]):
            assert np.array_equal(a, b), k
    assert np.count_nonzero(images[True, 1][0][..., 0]) > 1000   # the ground alone covers many beams
