"""The camera shader's noise (renderer_proc/shaders/textures.glsl): ``value_noise``, which shares hash work across a
cell's corners, and ``fbm``, which scales instead of dividing per octave and stops at the first octave faded whole,
give the bits of their readable forms ``value_noise_reference`` and ``fbm_reference`` on the GPU path the camera
renderer uses (llvmpipe); on a GPU, whose division and multiply-adds round otherwise, ``fbm`` holds to 1e-5 of its
reference."""
from __future__ import annotations

import numpy as np
import pytest

from renderer_proc.gl.backend import SHADER_DIR

pytestmark = pytest.mark.gl

#: evaluated image, px
SIZE = (256, 192)
#: (cells per px, offset in cells): fine and coarse sampling, negative and far-from-origin cells (the ground seen
#: at hundreds of metres through the finest octave)
SAMPLINGS = ((0.013, (-1.7, -0.3, 0.25)), (0.37, (3.1, -2.9, -7.5)), (5.3, (-640.0, 211.0, 3.0)),
             (0.5, (40000.5, -39000.25, 17.0)))

VERT = """#version 330
in vec2 in_pos;
void main() { gl_Position = vec4(in_pos, 0.0, 1.0); }
"""
FRAG = """#version 330
{textures}
uniform float u_scale;
uniform vec3 u_offset;
out float o_value;
// the painted steel's dust octaves (5 from 0.6 m) at a footprint of 0.4-100 mm per px (every octave faded in part or whole at some), p in m
float dust(vec3 p) {{ return fbm(p, 0.6, 5, 0.55, 0.0004 + 0.1 * fract(0.37 * p.x + 0.11 * p.y)); }}
float dust_reference(vec3 p) {{
    return fbm_reference(p, 0.6, 5, 0.55, 0.0004 + 0.1 * fract(0.37 * p.x + 0.11 * p.y));
}}
void main() {{
    vec3 p = u_offset + u_scale * vec3(gl_FragCoord.x, gl_FragCoord.y, 0.37 * gl_FragCoord.x - 0.61 * gl_FragCoord.y);
    o_value = {function}(p);
}}
"""


def _noise(ctx, function: str, scale: float, offset: tuple) -> np.ndarray:
    """(H, W) float32 ``function`` of textures.glsl over the image's points (FRAG)."""
    prog = ctx.program(vertex_shader=VERT, fragment_shader=FRAG.format(
        textures=(SHADER_DIR / "textures.glsl").read_text(), function=function))
    quad = ctx.buffer(np.array([-1, -1, 3, -1, -1, 3], np.float32).tobytes())
    vao = ctx.vertex_array(prog, [(quad, "2f", "in_pos")])
    rb = ctx.renderbuffer(SIZE, 1, dtype="f4")
    fbo = ctx.framebuffer([rb])
    try:
        prog["u_scale"].value = scale
        prog["u_offset"].value = offset
        fbo.use()
        fbo.clear(0.0, 0.0, 0.0, 0.0)
        vao.render()
        out = np.empty((SIZE[1], SIZE[0]), np.float32)
        fbo.read_into(out, components=1, dtype="f4")
        return out
    finally:
        for obj in (fbo, rb, vao, quad, prog):
            obj.release()


@pytest.mark.parametrize(("scale", "offset"), SAMPLINGS)
def test_value_noise_gives_the_bits_of_its_reference(ctx, scale, offset):
    fast = _noise(ctx, "value_noise", scale, offset)
    ref = _noise(ctx, "value_noise_reference", scale, offset)
    assert 0.0 <= ref.min() and ref.max() < 1.0 and ref.std() > 0.01       # a noise, not a constant
    np.testing.assert_array_equal(fast.view(np.uint32), ref.view(np.uint32))


@pytest.mark.parametrize(("scale", "offset"), [(0.0021, (-0.7, 1.3, 0.2)), (0.05, (-300.0, 120.0, 0.0))])
def test_fbm_gives_the_bits_of_its_reference(ctx, cpu_gl, scale, offset):
    fast = _noise(ctx, "dust", scale, offset)
    ref = _noise(ctx, "dust_reference", scale, offset)
    assert ref.std() > 0.01
    if cpu_gl:                                     # IEEE float32: scaling by 2^k and dividing by it are exact alike
        np.testing.assert_array_equal(fast.view(np.uint32), ref.view(np.uint32))
    else:                                          # a GPU's division and multiply-adds round otherwise
        np.testing.assert_allclose(fast, ref, rtol=0.0, atol=1e-5)           # 2.6e-6 at most on an NVIDIA H200


def test_the_comparison_sees_a_one_cell_shift(ctx):
    """The bit comparison can fail: the noise one cell along x is another image."""
    ref = _noise(ctx, "value_noise_reference", 0.37, (3.1, -2.9, -7.5))
    shifted = _noise(ctx, "value_noise", 0.37, (4.1, -2.9, -7.5))
    assert np.count_nonzero(shifted.view(np.uint32) != ref.view(np.uint32)) > ref.size // 2
