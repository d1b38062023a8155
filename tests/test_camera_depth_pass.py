"""The GL camera renderer's depth-only pass (renderer_proc.gl.camera): a renderer whose views read no colour draws
with camera_depth.frag, and its depth and labels are the textured pass's to the bit (docs/cameras.md)."""
from __future__ import annotations

import contextlib

import numpy as np
import pytest

from cosim.world.sensors import camera_pinhole, world_from_sensor
from renderer_proc.gl.camera import GLCameraRenderer
from tests.test_camera_gl import TOF, frame0

pytestmark = pytest.mark.gl


def _render(ctx, parts, night=False):
    s, state, scene = frame0(TOF)
    cam = s.cameras["tof"]
    pin = camera_pinhole(cam, s)
    r = GLCameraRenderer([pin], s.render.lighting, context=ctx, parts=parts)
    r.set_scene(scene)
    r.draw(0, world_from_sensor(cam, state))
    z = np.empty((pin.height, pin.width), np.float32)
    r.read_depth(0, z)
    lab = None
    if parts is None or "labels" in parts[0]:
        lab = np.empty((pin.height, pin.width), np.uint8)
        r.read_labels(0, lab)
    colour = r.colour
    with pytest.raises(ValueError, match="draws no rgb") if not colour else contextlib.nullcontext():
        r.read_rgb(0, np.empty((pin.height, pin.width, 4), np.uint8))
    r.close()
    return colour, z, lab


def test_depth_only_pass_gives_the_textured_pass_depth_and_labels_to_the_bit(ctx):
    colour, z_tex, lab_tex = _render(ctx, None)
    assert colour
    depth_only, z, lab = _render(ctx, [{"depth", "labels"}])
    assert not depth_only
    assert np.isfinite(z).mean() > 0.5                       # the cart and the ground fill most of the view
    assert z.tobytes() == z_tex.tobytes()
    assert lab.tobytes() == lab_tex.tobytes()
    _, z_bare, lab_bare = _render(ctx, [{"depth"}])          # no label attachment at all
    assert lab_bare is None and z_bare.tobytes() == z_tex.tobytes()
