"""The fast exact ray cast (cosim.world.fastcast): the scene's triangles are its exact surfaces, Embree against
the numpy ray cast beam for beam on real frames, closed forms, and the numpy fallback."""
from __future__ import annotations

import functools

import numpy as np
import pytest

from cosim.scenario.config import Scenario
from cosim.scenario.loader import load_scenario, packaged_scenarios
from cosim.world import fastcast
from cosim.world.beamtarget import beam_layout
from cosim.world.fastcast import cast_from
from cosim.world.geometry import make_transform
from cosim.world.heightfield import padded_heights, surface_height
from cosim.world.meshes import CYLINDER_SIDES, orthonormal_frames
from cosim.world.raycast import raycast
from cosim.world.scene import Boxes, Cylinders, HeightField, Scene, scene_from_state
from cosim.world.triangles import scene_triangles
from renderer_proc.codec import encode_depth
from renderer_proc.projection import world_from_sensor
from renderer_proc.sample import sample_frame

#: largest range difference between Embree (float32 traversal, float64 plane) and the numpy cast on the frames
#: below, m (measured 1.3e-7 m: the two compute the same intersection in float64 by different formulas)
AGREE_M = 1e-6
#: the codec's rounding step beta / 510 (Eqs 1-2 at the default codec), m
CODEC_STEP_M = 1.0 / 510.0


@functools.lru_cache(maxsize=1)
def frames():
    """(scenario, state, heights, stream) of sample frames of the default scene and of two other packaged
    scenarios (other carts, mounts, fills), the vehicles driving."""
    out = []
    names = ("default", "grazing_sensor", "soybeans")
    for name in names:
        sc = load_scenario(packaged_scenarios()[name])
        for t in (0.0, 3.0, 7.0):
            out.append((sc,) + sample_frame(sc, t))
    return out


@pytest.fixture(scope="module")
def embree():
    pytest.importorskip("embreex", reason="embreex (the 'fast' extra) is not installed on this platform")


def test_triangles_lie_on_the_exact_surfaces():
    """Every box vertex is a box corner, every cylinder vertex lies on its circle at a prism vertex angle and
    every grain vertex at the height of cosim.world.heightfield's surface, in the origin-relative frame."""
    sc = Scenario(format_version=1)
    state, h, stream = sample_frame(sc, 2.0)
    scene = scene_from_state(sc, state, h, stream)
    origin = np.array([3.0, -2.0, 4.0])
    v, f = scene_triangles(scene, origin)
    b, c, hf = scene.boxes, scene.cylinders, scene.heightfield
    nb, nc = 8 * len(b), (2 * CYLINDER_SIDES + 2) * len(c)
    assert f.min() == 0 and f.max() == len(v) - 1
    assert len(f) == 12 * len(b) + 4 * CYLINDER_SIDES * len(c) + 2 * (h.shape[0] + 1) * (h.shape[1] + 1)
    local = np.einsum("kij,kvi->kvj", b.world_from_box[:, :3, :3],
                      (v[:nb] + origin).reshape(len(b), 8, 3) - b.world_from_box[:, None, :3, 3])
    np.testing.assert_allclose(np.abs(local), np.broadcast_to(b.half_extents[:, None], local.shape), atol=1e-9)
    cv = (v[nb:nb + nc] + origin).reshape(len(c), -1, 3)[:, :2 * CYLINDER_SIDES] - c.p0[:, None]
    cl = np.einsum("kvi,kij->kvj", cv, orthonormal_frames(c.p1 - c.p0))
    np.testing.assert_allclose(np.hypot(cl[..., 0], cl[..., 1]), np.broadcast_to(c.radius[:, None], cl.shape[:2]),
                               rtol=1e-12)
    phi = np.arctan2(cl[:, :CYLINDER_SIDES, 1], cl[:, :CYLINDER_SIDES, 0])
    np.testing.assert_allclose(np.cos(phi), np.broadcast_to(np.cos(2 * np.pi * np.arange(CYLINDER_SIDES) /
                                                                    CYLINDER_SIDES), phi.shape), atol=1e-12)
    g = (v[nb + nc:] + origin - hf.world_from_grid[:3, 3]) @ hf.world_from_grid[:3, :3]
    z = surface_height(padded_heights(hf.heights), hf.cell_m, g[:, 0], g[:, 1])
    np.testing.assert_allclose(g[:, 2], z, atol=1e-9)


@pytest.mark.parametrize("k", range(9))
def test_embree_matches_numpy_beam_for_beam(embree, k):
    """On real frames (three packaged scenarios x three times) every beam's coverage agrees, ranges agree to
    AGREE_M and the encoded bytes are equal for at least 99.9 % of the beams (a range within a micrometre of a
    codec step boundary may round the other way)."""
    sc, state, h, stream = frames()[k]
    scene = scene_from_state(sc, state, h, stream)
    w = world_from_sensor(sc, state)
    d = beam_layout(sc.sensor.pattern).directions @ w[:3, :3].T
    ref = cast_from(scene, w[:3, 3], d, "numpy")
    got = cast_from(scene, w[:3, 3], d, "embree")
    assert np.isfinite(ref).mean() > 0.5
    np.testing.assert_array_equal(np.isfinite(got), np.isfinite(ref))
    both = np.isfinite(ref)
    assert np.max(np.abs(got[both] - ref[both])) < AGREE_M
    same = np.all(encode_depth(got[None], sc.sensor.codec) == encode_depth(ref[None], sc.sensor.codec), axis=-1)
    assert same.mean() >= 0.999


def test_ground_plane_at_grazing_incidence(embree):
    """The ground slab's top z = 0 seen from 1.5 m at elevations down to 0.5 deg (ranges to 172 m): t = h / sin(-el)
    exactly (float64 plane after the float32 traversal), misses above the horizon."""
    hf = HeightField(make_transform(np.eye(3), (0.0, 0.0, -30.0)), np.zeros((2, 2), np.float32), 0.1, 0.2, 0.2)
    none = Cylinders(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3), np.float32))
    ground = Boxes(make_transform(np.eye(3), (0.0, 0.0, -0.25))[None], np.array([[500.0, 500.0, 0.25]]),
                   np.ones((1, 3), np.float32))
    scene = Scene(ground, none, hf, (), 0)
    el = np.radians(np.concatenate([-np.geomspace(0.5, 89.0, 40), [0.5, 10.0]]))
    az = np.linspace(0.0, 2 * np.pi, len(el))
    d = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], axis=1)
    origin = np.array([12.3, -4.5, 1.5])
    t = cast_from(scene, origin, d, "embree")
    np.testing.assert_allclose(t[:-2], 1.5 / np.sin(-el[:-2]), rtol=1e-12)
    assert np.all(np.isinf(t[-2:]))


def test_edge_between_two_beams(embree):
    """A box edge exactly half-way (in angle) between two beams: the lower beam hits the face at its closed-form
    range, the upper one passes over the edge, as in the numpy cast."""
    box = Boxes(make_transform(np.eye(3), (10.0, 0.0, -1.0))[None], np.array([[1.0, 1.0, 1.0]]),
                np.ones((1, 3), np.float32))
    none = Cylinders(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3), np.float32))
    hf = HeightField(make_transform(np.eye(3), (0.0, 50.0, 0.0)), np.zeros((2, 2), np.float32), 0.1, 0.2, 0.2)
    scene = Scene(box, none, hf)
    edge = np.arctan2(0.0, 9.0)                         # the near top edge at z = 0, x = 9
    half = np.radians(0.05)
    el = np.array([edge - half, edge + half])
    d = np.stack([np.cos(el), np.zeros(2), np.sin(el)], axis=1)
    t = cast_from(scene, np.zeros(3), d, "embree")
    assert t[0] == pytest.approx(9.0 / np.cos(el[0]), rel=1e-12)
    assert np.isinf(t[1])
    np.testing.assert_array_equal(np.isfinite(t), np.isfinite(cast_from(scene, np.zeros(3), d, "numpy")))


def test_fallback_without_embree_is_the_numpy_cast(monkeypatch):
    """auto without embreex is the numpy ray cast bit for bit; an unknown backend is refused."""
    sc = Scenario(format_version=1)
    state, h, stream = sample_frame(sc, 1.0)
    scene = scene_from_state(sc, state, h, stream)
    w = world_from_sensor(sc, state)
    d = beam_layout(sc.sensor.pattern).directions[::7] @ w[:3, :3].T
    monkeypatch.setattr(fastcast, "embree_available", lambda: False)
    got = cast_from(scene, w[:3, 3], d)
    np.testing.assert_array_equal(got, raycast(scene, np.broadcast_to(w[:3, 3], d.shape), d))
    with pytest.raises(ValueError, match="backend must be one of"):
        cast_from(scene, w[:3, 3], d, "optix")
