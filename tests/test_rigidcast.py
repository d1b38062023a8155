"""The ray cast with the rigid bodies built once per run (cosim.world.rigidcast): beam for beam against the numpy
ray cast on real frames, across frames (the grain surface refitted, instance pools grown and hidden), the ground
plane's shortcut and its fallback, Embree's handles, and the caster a renderer reports."""
from __future__ import annotations

import ctypes
import functools
from dataclasses import replace

import numpy as np
import pytest

from cosim.scenario.config import Scenario
from cosim.scenario.loader import load_scenario, packaged_scenarios
from cosim.world import embree_api, fastcast
from cosim.world.beamtarget import beam_layout
from cosim.world.fastcast import CASTERS, cast_from, make_caster
from cosim.world.parts import entity_parts
from cosim.world.scene import Cylinders, scene_from_state
from renderer_proc.projection import world_from_sensor
from renderer_proc.sample import sample_frame
from renderer_proc.summary import summarize

#: largest range difference against the numpy ray cast, m (as tests/test_fastcast.py: both intersect in
#: float64; measured below 1e-13 m)
AGREE_M = 1e-6

embree = pytest.importorskip("embreex", reason="embreex (the 'fast' extra) is not installed on this platform")


@functools.lru_cache(maxsize=None)
def scenario(name: str):
    return load_scenario(packaged_scenarios()[name])


def rays(sc, t_s: float, heights=None):
    """(scene, origin, world directions) of the sample frame at ``t_s``, optionally with other grain heights."""
    state, h, stream = sample_frame(sc, t_s)
    scene = scene_from_state(sc, state, h if heights is None else heights, stream)
    w = world_from_sensor(sc, state)
    return scene, w[:3, 3], beam_layout(sc.sensor.pattern).directions @ w[:3, :3].T


def assert_agrees(got: np.ndarray, ref: np.ndarray, min_hit: float = 0.5) -> None:
    np.testing.assert_array_equal(np.isfinite(got), np.isfinite(ref))
    both = np.isfinite(ref)
    assert both.mean() > min_hit
    assert np.max(np.abs(got[both] - ref[both])) < AGREE_M


@pytest.mark.parametrize("name", ["default", "grazing_sensor", "soybeans"])
def test_matches_numpy_beam_for_beam_over_frames(name):
    """One caster over three frames of a scenario (vehicles moved, stream and heap different): every beam's
    coverage and range as the numpy ray cast of the same scene."""
    sc = scenario(name)
    caster = make_caster(entity_parts(sc))
    assert caster.name == "embree-static"
    try:
        for t in (0.0, 3.0, 7.0):
            scene, o, d = rays(sc, t)
            assert_agrees(caster.cast(scene, o, d), cast_from(scene, o, d, "numpy"))
    finally:
        caster.close()


def test_grain_surface_refit_and_pools():
    """Heights changed between frames (a refit, not a rebuild) and the stream cut short then grown again (prism
    instances hidden and shown): each frame as a fresh numpy cast."""
    sc = Scenario(format_version=1)
    caster = make_caster(entity_parts(sc))
    rng = np.random.default_rng(3)
    try:
        for k in range(4):
            scene, o, d = rays(sc, 1.0)
            h = np.asarray(scene.heightfield.heights) + rng.uniform(0.0, 0.4, scene.heightfield.heights.shape)
            scene = scene_from_state(sc, *sample_frame(sc, 1.0)[:1], h.astype(np.float32), sample_frame(sc, 1.0)[2])
            c = scene.cylinders
            keep = len(c) - (8 if k % 2 else 0)                 # odd frames: eight stream segments fewer
            scene = replace(scene, cylinders=Cylinders(c.p0[:keep], c.p1[:keep], c.radius[:keep], c.colour[:keep]))
            assert_agrees(caster.cast(scene, o, d), cast_from(scene, o, d, "numpy"))
    finally:
        caster.close()


def test_ground_plane_below_and_its_fallback():
    """From above the slab the ground is its top face's plane (no solid in Embree); from beside it (outside its
    extent) the slab is a solid again: both as the numpy cast."""
    sc = Scenario(format_version=1)
    caster = make_caster(entity_parts(sc))
    try:
        scene, o, d = rays(sc, 2.0)
        g = scene.boxes.world_from_box[scene.ground_box]
        assert fastcast_top(scene, o, d) is not None
        assert_agrees(caster.cast(scene, o, d), cast_from(scene, o, d, "numpy"))
        half = scene.boxes.half_extents[scene.ground_box]
        outside = g[:3, 3] + np.array([half[0] + 3.0, 0.0, 0.5])     # beside the slab, 0.5 m above its top
        el = np.radians(np.linspace(-30.0, 10.0, 41))
        side = np.stack([-np.cos(el), np.zeros_like(el), np.sin(el)], axis=1)
        assert fastcast_top(scene, outside, side) is None
        ref = cast_from(scene, outside, side, "numpy")
        assert np.isfinite(ref).sum() > 10                       # the slab's side face and top seen from beside
        assert_agrees(caster.cast(scene, outside, side), ref, min_hit=0.25)
    finally:
        caster.close()


def fastcast_top(scene, o, d):
    from cosim.world.rigidcast import top_face_from_above

    b = scene.boxes
    return top_face_from_above(b.world_from_box[scene.ground_box], b.half_extents[scene.ground_box], o, d)


def test_scene_without_poses_and_numpy_backend():
    """A scene not built by scene_from_state (no poses) is cast per frame; backend numpy never uses Embree."""
    sc = Scenario(format_version=1)
    scene, o, d = rays(sc, 1.0)
    bare = replace(scene, poses=None)
    caster = make_caster(entity_parts(sc))
    try:
        np.testing.assert_array_equal(caster.cast(bare, o, d[::5]), cast_from(bare, o, d[::5], "embree"))
    finally:
        caster.close()
    numpy_caster = make_caster(entity_parts(sc), "numpy")
    assert numpy_caster.name == "numpy"
    np.testing.assert_array_equal(numpy_caster.cast(scene, o, d[::9]), cast_from(scene, o, d[::9], "numpy"))
    assert make_caster(None).name == "embree"
    with pytest.raises(ValueError, match="backend must be one of"):
        make_caster(None, "optix")


def test_layout_checks_refuse_other_objects(monkeypatch):
    """handles() reads embreex's objects only after checking their layout; any mismatch is EmbreeUnavailable,
    and make_caster then falls back to the per-frame Embree cast."""
    from embreex import rtcore, rtcore_scene

    dev = rtcore.EmbreeDevice()
    top = rtcore_scene.EmbreeScene(dev)
    scene_handle, device_handle = embree_api.handles(top, dev)
    assert scene_handle and device_handle
    assert embree_api.api().rtcGetDeviceError(ctypes.c_void_p(device_handle)) == 0
    with pytest.raises(embree_api.EmbreeUnavailable, match="not 40 / 24"):
        embree_api.handles(object(), dev)
    with pytest.raises(embree_api.EmbreeUnavailable, match="device where expected"):
        embree_api.handles(top, rtcore.EmbreeDevice())
    assert top.is_committed == 0                                 # the probe leaves the field as it was

    def refuse(*args):
        raise embree_api.EmbreeUnavailable("layout")

    monkeypatch.setattr(embree_api, "handles", refuse)
    assert make_caster(entity_parts(Scenario(format_version=1))).name == "embree"
    monkeypatch.setattr(fastcast, "embree_available", lambda: False)
    assert make_caster(entity_parts(Scenario(format_version=1))).name == "numpy"


def test_renderer_summary_names_the_caster():
    """summary.json's ray_caster from render_state.ray_caster's last code; nothing for a GL run."""
    sc = Scenario(format_version=1)
    assert summarize(sc, {"render_state.ray_caster": np.array([3.0, 3.0])}, None) == {"ray_caster": "embree-static"}
    assert summarize(sc, {"render_state.ray_caster": np.array([1.0])}, None) == {"ray_caster": CASTERS[1]}
    assert summarize(sc, {"render_state.render_ms": np.array([2.0])}, None) == {}


@pytest.mark.filterwarnings("ignore:invalid value encountered:RuntimeWarning")
def test_degenerate_solids_are_not_cast():
    """Solids without volume never reach Embree nor an inverse: the auger's last run-out frame (every stream
    segment of zero radius, which raised LinAlgError), a prism of zero length, an empty
    stream and a grain surface all at the floor, frame after frame on one caster (instances hidden, then shown
    again): every beam as the numpy cast of the same scene."""
    sc = Scenario(format_version=1)
    caster = make_caster(entity_parts(sc))
    try:
        scene, o, d = rays(sc, 3.0)
        c, n_stream = scene.cylinders, int(np.sum(scene.cylinders.radius < 0.16))
        assert n_stream > 10
        zero_r = c.radius.copy()
        zero_r[-n_stream:] = 0.0
        short = c.p1.copy()
        short[-n_stream:-n_stream + 3] = c.p0[-n_stream:-n_stream + 3]          # three of zero length
        cases = {
            "zero radius": replace(scene, cylinders=Cylinders(c.p0, c.p1, zero_r, c.colour)),
            "as before": scene,
            "zero length": replace(scene, cylinders=Cylinders(c.p0, short, c.radius, c.colour)),
            "no stream": replace(scene, cylinders=Cylinders(c.p0[:-n_stream], c.p1[:-n_stream],
                                                            c.radius[:-n_stream], c.colour[:-n_stream])),
            "grain at the floor": rays(sc, 3.0, np.zeros_like(scene.heightfield.heights))[0],
            "again": scene,
        }
        for name, s in cases.items():
            assert_agrees(caster.cast(s, o, d), cast_from(s, o, d, "numpy"), min_hit=0.3), name
    finally:
        caster.close()


def test_has_volume():
    """Scaled rotations have volume; a zero axis, a nearly coplanar frame or a non-finite entry does not."""
    from cosim.world.rigidcast import has_volume

    rot = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    lin = np.stack([rot * [0.1, 0.1, 2.0], rot * [0.0, 0.0, 2.0], rot * [0.3, 0.3, 0.0],
                    np.array([[1.0, 1.0, 0.0], [0.0, 1e-12, 0.0], [0.0, 0.0, 1.0]]), np.full((3, 3), np.nan),
                    rot * [1e-6, 1e-6, 1e-6]])
    trans = np.zeros((len(lin), 3))
    assert has_volume(lin, trans).tolist() == [True, False, False, False, False, True]
    trans[0, 1] = np.inf
    assert not has_volume(lin, trans)[0]


def test_stream_segments_without_surface_are_dropped():
    """The scene keeps no stream segment of zero radius (the run-out's last frame) nor of zero length."""
    from cosim.world.scene import _stream_cylinders

    rows = np.array([[0.0, 0.0, 3.0, 0.1], [0.0, 0.0, 2.0, 0.1], [0.0, 0.0, 2.0, 0.1], [0.0, 0.0, 1.0, 0.0],
                     [0.0, 0.0, 0.5, 0.0]])
    p0, p1, r = _stream_cylinders(rows, 5)
    np.testing.assert_array_equal(p0[:, 2], [3.0, 2.0])            # 3 -> 2, 2 -> 1 (mean radius 0.05); 1 -> 0.5 gone
    np.testing.assert_array_equal(r, [0.1, 0.05])
