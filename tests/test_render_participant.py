"""The renderer participant over an in-process segment (mock and GL), its blocks, and GL-free imports."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from cosim.errors import FrameMismatch, RendererUnavailable
from cosim.scenario.config import Scenario
from cosim.testing.renderer_inputs import dynamics_blocks, publish
from cosim.world.fastcast import CASTERS, embree_available
from cosim.world.rig import plan_rig
from renderer_proc.blocks import declare_blocks
from renderer_proc.codec import decode_depth
from renderer_proc.participant import create
from renderer_proc.sample import sample_frame
from shm_schema import Schema, Segment

SMALL = {"rig": "fixed", "cameras": 2, "width_px": 64, "height_px": 48, "hfov_deg": 60.0}


def scenario(**kw) -> Scenario:
    return Scenario.model_validate({"format_version": 1, **kw})


def segment_for(s: Scenario, frame: int = 0):
    state, heights, stream = sample_frame(s)
    seg = Segment.local(Schema(dynamics_blocks(state, heights) + declare_blocks(s), ["dynamics", "renderer"]))
    publish(seg, state, heights, stream, frame)
    return seg, state


def test_blocks_follow_rig_and_options():
    s = scenario(render={**SMALL, "float_depth": True, "rgb": "auto"}, viewer=False)
    names = {b.name: b for b in declare_blocks(s)}
    assert set(names) == {"render_state", "cam0_depth", "cam1_depth", "cam0_zf", "cam1_zf"}
    assert names["cam0_depth"].shape == (48, 64, 4) and names["cam0_depth"].dtype == "|u1"
    assert names["cam1_zf"].shape == (48, 64) and names["cam1_zf"].dtype == "<f4"
    with_viewer = {b.name for b in declare_blocks(scenario(render=SMALL, viewer=True))}
    assert {"cam0_rgb", "cam1_rgb"} <= with_viewer
    assert not any(n.endswith("_rgb") for n in
                   (b.name for b in declare_blocks(scenario(render={**SMALL, "rgb": "off"}, viewer=True))))
    mock = scenario(renderer="mock", render={**SMALL, "mock_scale": 0.5})
    assert {b.name: b for b in declare_blocks(mock)}["cam0_depth"].shape == (24, 32, 4)
    assert declare_blocks(scenario(renderer="none", feedback="ground_truth")) == []
    auto = Scenario(format_version=1)
    cams = plan_rig(auto).cameras
    assert [b.name for b in declare_blocks(auto) if b.name.endswith("_depth")] == [f"{c.name}_depth" for c in cams]


@pytest.mark.parametrize("backend", ["mock", "gl"])
def test_participant_renders_into_blocks(backend):
    s = scenario(renderer=backend, render={**SMALL, "float_depth": True, "rgb": "on"})
    seg, state = segment_for(s)
    views = {n: seg.view(n) for n in ("cam0_depth", "cam1_depth", "cam0_zf", "cam0_rgb")}
    p = create(s)
    assert p.name == "renderer"
    try:
        p.start(seg)
    except RendererUnavailable as exc:
        pytest.skip(str(exc))
    try:
        p.step(0)
        for name, v in views.items():
            assert seg.view(name) is v                  # written in place, no new array
            assert seg.frame_of(name) == 0
        depth = decode_depth(views["cam0_depth"], s.sensor.codec)
        zf = views["cam0_zf"]
        assert np.isfinite(depth).mean() > 0.5
        np.testing.assert_array_equal(np.isfinite(depth), np.isfinite(zf))
        assert np.nanmax(np.abs(depth - zf)) <= s.sensor.codec.bound_m + 1e-4
        st = seg.view("render_state")
        assert st.render_ms > 0 and 0.5 < st.valid_fraction <= 1.0
        alpha = [views[n][..., 3] for n in ("cam0_depth", "cam1_depth")]
        assert st.valid_fraction == sum(np.count_nonzero(a) for a in alpha) / sum(a.size for a in alpha)
        if backend == "mock":                           # the ray caster that ran, for summary.json
            assert CASTERS[int(st.ray_caster)] == p.backend.caster.name
            if embree_available():
                assert p.backend.caster.name == "embree-static"
        else:
            assert "ray_caster" not in st.array.dtype.names
        with pytest.raises(FrameMismatch, match="expected dyn_state of frame 1, found frame 0"):
            p.step(1)
    finally:
        p.close()
        p.close()


def test_gl_and_mock_participants_agree():
    base = {"render": {**SMALL, "cameras": 1, "width_px": 120, "height_px": 90, "mock_scale": 1.0}}
    out = {}
    for backend in ("mock", "gl"):
        s = scenario(renderer=backend, **base)
        seg, _ = segment_for(s)
        p = create(s)
        try:
            p.start(seg)
        except RendererUnavailable as exc:
            pytest.skip(str(exc))
        p.step(0)
        p.close()
        out[backend] = decode_depth(seg.view("cam0_depth"), s.sensor.codec)
    both = np.isfinite(out["gl"]) & np.isfinite(out["mock"])
    assert np.mean(np.abs(out["gl"] - out["mock"])[both] <= 0.01) >= 0.99


def test_missing_input_block_is_named():
    s = scenario(renderer="mock", render=SMALL)
    seg = Segment.local(Schema(declare_blocks(s), ["renderer"]))
    with pytest.raises(KeyError, match="dyn_state"):
        create(s).start(seg)


def test_gl_unavailable_names_cause_and_mock(monkeypatch):
    import moderngl

    def fail(**kw):
        raise Exception("libEGL not found")

    monkeypatch.setattr(moderngl, "create_context", fail)
    s = scenario(renderer="gl", render=SMALL)
    seg, _ = segment_for(s)
    p = create(s)
    with pytest.raises(RendererUnavailable, match=r"libEGL not found.*--renderer mock"):
        p.start(seg)
    p.close()


def test_import_never_touches_gl():
    code = ("import sys, renderer_proc, renderer_proc.participant, renderer_proc.blocks, cosim.world.rig, "
            "cosim.world.scene, cosim.world.raycast, renderer_proc.mock.backend, renderer_proc.gl.backend\n"
            "assert 'moderngl' not in sys.modules, 'moderngl imported'\n"
            "assert not any(m.startswith('glcontext') for m in sys.modules)\n")
    subprocess.run([sys.executable, "-c", code], check=True, cwd=str(__import__("pathlib").Path(__file__).parents[1]))


def test_two_gl_renderers_in_one_thread_each_draw_into_their_own_context():
    """Several GL renderers in one thread (in-process simulations side by side), each with its own context: a
    renderer's images are those it drew alone, though another renderer (another pattern) was made and drew in
    between (moderngl draws into whichever context is current; each renderer makes its own current when a frame
    starts)."""
    from cosim.world.beamtarget import beam_layout
    from cosim.world.scene import scene_from_state
    from renderer_proc.gl.beam import GLBeamRenderer
    from renderer_proc.projection import world_from_sensor

    s = Scenario(format_version=1)
    lay = beam_layout(s.sensor.pattern)
    other = beam_layout(s.sensor.pattern.model_copy(update={"azimuth_count": 120, "elevation_count": 90}))
    state, heights, stream = sample_frame(s, 2.0)
    pose = world_from_sensor(s, state)
    scenes = [scene_from_state(s, state, heights + np.float32(dz), stream) for dz in (0.0, 0.4)]

    def frame(r, layout, scene):
        r.set_scene(scene)
        r.draw(0, pose)
        img = np.zeros(layout.shape + (4,), np.uint8)
        r.read_depth(0, img)
        return img

    try:
        first = GLBeamRenderer(lay, s.sensor.codec)
    except RendererUnavailable as exc:
        pytest.skip(str(exc))
    second = None
    try:
        alone = [frame(first, lay, sc) for sc in scenes]
        assert not np.array_equal(alone[0], alone[1])
        second = GLBeamRenderer(other, s.sensor.codec)              # made last: its context is current
        for sc, ref in zip(scenes, alone):
            frame(second, other, sc)
            np.testing.assert_array_equal(frame(first, lay, sc), ref)
    finally:
        if second is not None:
            second.close()
        first.close()
