"""What the camera textures' noise costs on the GL the renderer runs on (docs/cameras.md): the value noise that
``renderer_proc/shaders/textures.glsl`` hashes per octave, against the same octaves looked up in baked textures.

One full view of the packaged stereo head's eye (``width`` x ``height`` px, 1024 x 544) is shaded with one fragment
shader per arm, the steel's dust at every pixel: 5 octaves from 0.6 m, gain 0.55, the surface at 4 mm a pixel (no
octave faded), the point p = (x, y) px * 4 mm on the plane z = 0.37 m. Arms:

* ``hashed``: ``textures.glsl``'s ``fbm`` (8 lattice corners hashed an octave, blended by smoothstep weights);
* ``volume``: each octave one trilinear lookup in a baked volume of the same value noise (32 cells a period, 4
  texels a cell: 128^3 half floats, 4 MiB), with ``textureLod`` at the octave's level 0;
* ``volume_mip``: the same volume mipmapped, each octave at its own level of detail (trilinear between levels);
* ``plane``: each octave one lookup in a 2D texture of the noise on one lattice plane (128 x 128 half floats);
* ``plane_fbm``: the whole sum of octaves baked into one mipmapped 2D texture (2048 x 2048 half floats, 8 MiB
  and its levels): one lookup a pixel. A surface textured this way needs a 2D parametrisation (a plane per face
  or three planes blended), which a heightfield's slopes and a cylinder's side do not have exactly.

Per arm: thread CPU ms a view (llvmpipe in the calling thread, ``LP_NUM_THREADS=0`` set before GL loads: the case
runs in a fresh worker process), the minimum over ``repeats`` renders after one to compile and warm (the minimum:
the least disturbed render of a deterministic workload), and the mean and standard deviation of the image's
values (the bakes sample the same noise; their statistics say that the arms compare like with like).
"""
from __future__ import annotations

import os
import time

import numpy as np
from harness import Context, case

__all__ = ["bake_plane_fbm", "bake_volume", "hash3", "lattice", "texture_cost"]

#: lattice cells a period of the baked textures, and texels a cell
PERIOD, TEXELS = 32, 4
#: the dust's octaves: coarsest wavelength m, count, amplitude ratio; the surface's size of a pixel, m
W0, OCTAVES, GAIN, FOOTPRINT = 0.6, 5, 0.55, 0.004

VERT = """#version 330
void main() { gl_Position = vec4(vec2(gl_VertexID & 1, gl_VertexID >> 1) * 4.0 - 1.0, 0.0, 1.0); }
"""
#: per arm the fragment shader's body: p (m) and q = p / W0 (cells of the first octave) are given
BODIES = {
    "hashed": "return fbm(p, W0, OCTAVES, GAIN, FOOTPRINT);",
    "volume": """float s = 0.0, a = 1.0;
    for (int k = 0; k < OCTAVES; ++k) {
        s += a * (textureLod(u_volume, (q * exp2(float(k)) + float(k) * 17.0) / PERIOD, 0.0).r - 0.5);
        a *= GAIN;
    }
    return s;""",
    "volume_mip": """float s = 0.0, a = 1.0, lod = log2(TEXELS * FOOTPRINT / W0);
    for (int k = 0; k < OCTAVES; ++k) {
        s += a * (textureLod(u_volume_mip, (q * exp2(float(k)) + float(k) * 17.0) / PERIOD, lod).r - 0.5);
        a *= GAIN;
        lod += 1.0;
    }
    return s;""",
    "plane": """float s = 0.0, a = 1.0;
    for (int k = 0; k < OCTAVES; ++k) {
        s += a * (textureLod(u_plane, (q.xy * exp2(float(k)) + float(k) * 17.0) / PERIOD, 0.0).r - 0.5);
        a *= GAIN;
    }
    return s;""",
    "plane_fbm": "return texture(u_plane_fbm, q.xy / PERIOD).r;",
}
FRAG = """#version 330
{textures}
uniform sampler3D u_volume;
uniform sampler3D u_volume_mip;
uniform sampler2D u_plane;
uniform sampler2D u_plane_fbm;
const float W0 = {w0}, GAIN = {gain}, FOOTPRINT = {footprint}, PERIOD = {period}.0, TEXELS = {texels}.0;
const int OCTAVES = {octaves};
out float o_value;
float noise_at(vec3 p, vec3 q) {{
    {body}
}}
void main() {{
    vec3 p = vec3(gl_FragCoord.xy * FOOTPRINT, 0.37);
    o_value = noise_at(p, p / W0);
}}
"""


def hash3(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    """The shader's 3D integer hash (``hash3`` in textures.glsl, PCG-style mixing) of integer arrays of one shape,
    uint32, wrapping as GLSL's unsigned arithmetic does."""
    with np.errstate(over="ignore"):
        vx, vy, vz = (np.asarray(a).astype(np.uint32) * np.uint32(1664525) + np.uint32(1013904223) for a in (x, y, z))
        for _ in range(2):
            vx = vx + vy * vz
            vy = vy + vz * vx
            vz = vz + vx * vy
            if _ == 0:
                vx, vy, vz = (v ^ (v >> np.uint32(16)) for v in (vx, vy, vz))
    return vx ^ vy ^ vz


def lattice(shape: tuple[int, ...]) -> np.ndarray:
    """The value noise's lattice values [0, 1) over cells ``shape`` ([z,] y, x from 0): the shader's ``rand3``, the
    hash's low 24 bits over 2^24 (cells of a 2D shape on the plane z = 0)."""
    idx = np.meshgrid(*[np.arange(n, dtype=np.int64) + 1048576 for n in shape], indexing="ij")
    z = idx[0] if len(shape) == 3 else np.full(shape, 1048576, np.int64)
    y, x = idx[-2], idx[-1]
    return (hash3(x, y, z) & np.uint32(0xFFFFFF)).astype(np.float64) / 16777216.0


def _blend(values: np.ndarray, axis: int, per_cell: int) -> np.ndarray:
    """Smoothstep-blend the periodic lattice ``values`` along ``axis`` at ``per_cell`` texel centres a cell."""
    n = values.shape[axis]
    t = (np.arange(n * per_cell) + 0.5) / per_cell
    i = np.floor(t).astype(np.int64)
    u = (t - i) ** 2 * (3.0 - 2.0 * (t - i))
    shape = [1] * values.ndim
    shape[axis] = -1
    a, b = np.take(values, i % n, axis=axis), np.take(values, (i + 1) % n, axis=axis)
    return a + (b - a) * u.reshape(shape)


def bake_volume(period: int = PERIOD, texels: int = TEXELS) -> np.ndarray:
    """(N, N, N) float32 [z, y, x], N = period * texels: the value noise at the texel centres of one period (a
    texel i along an axis at (i + 0.5) / texels cells, where GL samples texel i of a texture read at q / period)."""
    v = lattice((period,) * 3)
    for axis in (2, 1, 0):
        v = _blend(v, axis, texels)
    return v.astype(np.float32)


def bake_plane_fbm(octaves: int = OCTAVES, gain: float = GAIN, period: int = PERIOD, texels: int = TEXELS) -> np.ndarray:
    """(N, N) float32 [y, x], N = period * 2^(octaves - 1) * texels: the sum of ``octaves`` octaves of the plane's
    value noise (octave k: 2^k cells a cell of the first, amplitude gain^k, minus its mean 0.5), at texel centres of
    one period of the first octave; the finest octave gets ``texels`` texels a cell."""
    n = period * texels << (octaves - 1)
    out = np.zeros((n, n))
    for k in range(octaves):
        cells = period << k
        v = lattice((cells, cells))
        for axis in (1, 0):
            v = _blend(v, axis, n // cells)
        out += gain ** k * (v - 0.5)
    return out.astype(np.float32)


def _textures(ctx) -> list:
    """The baked volume (unit 1; mipmapped at unit 2), the plane's noise (3) and the plane's fbm (4, mipmapped) as
    GL textures."""
    import moderngl

    vol = bake_volume()
    plane = _blend(_blend(lattice((PERIOD, PERIOD)), 1, TEXELS), 0, TEXELS).astype(np.float32)
    fbm = bake_plane_fbm()
    made = [ctx.texture3d(vol.shape[::-1], 1, vol.astype(np.float16).tobytes(), dtype="f2"),
            ctx.texture3d(vol.shape[::-1], 1, vol.astype(np.float16).tobytes(), dtype="f2"),
            ctx.texture(plane.shape[::-1], 1, plane.astype(np.float16).tobytes(), dtype="f2"),
            ctx.texture(fbm.shape[::-1], 1, fbm.astype(np.float16).tobytes(), dtype="f2")]
    for unit, tex in enumerate(made, start=1):
        tex.repeat_x = tex.repeat_y = True
        if unit in (1, 2):
            tex.repeat_z = True
        mip = unit in (2, 4)
        tex.filter = (moderngl.LINEAR_MIPMAP_LINEAR if mip else moderngl.LINEAR, moderngl.LINEAR)
        if mip:
            tex.build_mipmaps()
        tex.use(unit)
    return made


def _arm(ctx, fbo, name: str, repeats: int) -> tuple[float, np.ndarray]:
    """(thread CPU ms of the least disturbed of ``repeats`` renders, the image) of arm ``name``."""
    from renderer_proc.gl.backend import SHADER_DIR

    frag = FRAG.format(textures=(SHADER_DIR / "textures.glsl").read_text(), body=BODIES[name], w0=W0,
                       gain=GAIN, footprint=FOOTPRINT, period=PERIOD, texels=TEXELS, octaves=OCTAVES)
    prog = ctx.program(vertex_shader=VERT, fragment_shader=frag)
    for unit, uniform in enumerate(("u_volume", "u_volume_mip", "u_plane", "u_plane_fbm"), start=1):
        if uniform in prog:
            prog[uniform].value = unit
    vao = ctx.vertex_array(prog, [])
    try:
        fbo.use()
        vao.render(vertices=3)                  # compiles and warms
        ctx.finish()
        best = float("inf")
        for _ in range(repeats):
            c = time.thread_time()
            vao.render(vertices=3)
            ctx.finish()
            best = min(best, time.thread_time() - c)
        w, h = fbo.size
        img = np.empty((h, w), np.float32)
        fbo.read_into(img, components=1, dtype="f4")
        return 1e3 * best, img
    finally:
        vao.release()
        prog.release()


@case("texture_cost", "the camera textures' noise per view: hashed per octave (the shader's) against baked textures "
      "looked up (a volume, mipmapped or not, a plane a octave, the whole fbm in one mipmapped plane)",
      options={"width": 1024, "height": 544, "repeats": 5, "arms": ",".join(BODIES)},
      quick={"width": 256, "height": 136, "repeats": 2})
def texture_cost(ctx: Context) -> dict:
    """Thread CPU ms a view and the image's statistics per arm (module docstring)."""
    os.environ.setdefault("LP_NUM_THREADS", "0")                  # before GL loads: llvmpipe in the calling thread
    from renderer_proc.gl.backend import create_gl_context

    names = [a for a in ctx["arms"].split(",") if a]
    unknown = [a for a in names if a not in BODIES]
    if unknown:
        raise ValueError(f"texture_cost: no arm {', '.join(unknown)} (arms: {', '.join(BODIES)})")
    gl = create_gl_context()
    try:
        _textures(gl)
        fbo = gl.framebuffer([gl.renderbuffer((ctx["width"], ctx["height"]), 1, dtype="f4")])
        out = {}
        for name in names:
            ms, img = _arm(gl, fbo, name, ctx["repeats"])
            out[name] = {"thread CPU ms a view": ms, "mean": float(img.mean()), "std": float(img.std())}
        if "hashed" in out:
            for row in out.values():
                row["CPU / hashed"] = row["thread CPU ms a view"] / out["hashed"]["thread CPU ms a view"]
        return {f"noise a view, {ctx['width']} x {ctx['height']} px (LP_NUM_THREADS={os.environ['LP_NUM_THREADS']})":
                out}
    finally:
        gl.release()


#: texture_scene's arms: how each ``fbm(`` call in ``albedo`` is replaced (None: kept, the shader's own)
SCENE_ARMS = {"hashed": None,
              "lookup": "fbm_lookup(",          # one mipmapped lookup of a 2D texture (a baked texture's cost)
              "none": "fbm_none("}              # no noise: what the octaves cost altogether
#: the stand-ins, inserted before ``albedo``; u_baked: a 2048 x 2048 half-float texture, mipmapped, on unit 6
STAND_INS = """
uniform sampler2D u_baked;
float fbm_lookup(vec3 p, float w0, int n, float gain, float footprint) {
    return texture(u_baked, p.xy / (32.0 * w0)).r - 0.5;
}
float fbm_none(vec3 p, float w0, int n, float gain, float footprint) {
    return 1e-9 * (p.x + w0 + float(n) + gain + footprint);
}
"""


def scene_textures(arm: str) -> str:
    """``textures.glsl`` with ``albedo``'s noise as arm ``arm`` of :data:`SCENE_ARMS` has it."""
    from renderer_proc.gl.backend import SHADER_DIR

    text = (SHADER_DIR / "textures.glsl").read_text()
    if SCENE_ARMS[arm] is None:
        return text
    head, sep, tail = text.partition("vec3 albedo(")
    return head + STAND_INS + sep + tail.replace("fbm(", SCENE_ARMS[arm])


def _captured_frames(scenario, frames: int):
    """(the camera renderer's pins, lighting and context, [(scene, light, [(view, pose)])]) of the first ``frames``
    frames of ``scenario`` that draw every camera view, run in-process (the session is left open: it owns the GL
    context)."""
    import copy

    import renderer_proc.gl.camera as gc
    from cosim.runtime.inprocess import InProcessSession

    caps, pending = [], {}
    set_scene, draw = gc.GLCameraRenderer.set_scene, gc.GLCameraRenderer.draw

    def record_scene(self, scene, light=None):
        pending.update(scene=copy.deepcopy(scene), light=None if light is None else np.array(light), draws=[])
        return set_scene(self, scene, light)

    def record_draw(self, k, pose):
        pending["draws"].append((k, np.array(pose)))
        if len(pending["draws"]) == len(self.views):
            caps.append((pending["scene"], pending["light"], list(pending["draws"])))
        return draw(self, k, pose)

    gc.GLCameraRenderer.set_scene, gc.GLCameraRenderer.draw = record_scene, record_draw
    try:
        sess = InProcessSession(scenario)
        while len(caps) < frames and not sess.done:
            sess.step()
    finally:
        gc.GLCameraRenderer.set_scene, gc.GLCameraRenderer.draw = set_scene, draw
    return sess, caps


def _scene_renderers(backend, arms: list[str]) -> list:
    """A camera renderer per arm on ``backend``'s views and context, its shader's noise as the arm has it."""
    import moderngl

    import renderer_proc.gl.camera as gc
    from renderer_proc.gl.backend import SHADER_DIR

    baked = backend.ctx.texture((2048, 2048), 1, np.random.default_rng(0).random((2048, 2048)).astype(
        np.float16).tobytes(), dtype="f2")
    baked.repeat_x = baked.repeat_y = True
    baked.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
    baked.build_mipmaps()
    baked.use(6)
    source, out = gc.camera_fragment_source, []
    head, body = (SHADER_DIR / "camera.frag").read_text().split("\n", 1)
    try:
        for arm in arms:
            gc.camera_fragment_source = lambda arm=arm: "\n".join([head, scene_textures(arm), body])
            r = gc.GLCameraRenderer(backend.pins, backend.lighting, context=backend.ctx)
            for prog in (r.prog_inst, r.prog_hf):
                if "u_baked" in prog:
                    prog["u_baked"].value = 6
            out.append(r)
    finally:
        gc.camera_fragment_source = source
    return out


@case("texture_scene", "the camera shader on a scenario's captured frames with its noise hashed (the shader's), "
      "each fbm one mipmapped texture lookup (a baked texture's cost), or none (the octaves' share)",
      options={"scenario": "stereo_spout", "frames": 4, "repeats": 3, "arms": ",".join(SCENE_ARMS)},
      quick={"frames": 1, "repeats": 1})
def texture_scene(ctx: Context) -> dict:
    """Thread CPU ms per frame (upload, draw and read of every camera view; llvmpipe in the calling thread) of each
    arm on the same captured frames, arms interleaved frame by frame ``repeats`` times: medians, and each frame's
    ratio to ``hashed`` (median over frames of the median over repeats). With ``hashed`` among the arms, each stereo
    camera's matcher on its rendered pairs too (:func:`_matcher_times`): what a map costs perception's matcher
    beside what its pair costs the renderer."""
    import statistics

    os.environ.setdefault("LP_NUM_THREADS", "0")                  # before GL loads: llvmpipe in the calling thread
    arms = [a for a in ctx["arms"].split(",") if a]
    if not set(arms) <= set(SCENE_ARMS):
        raise ValueError(f"texture_scene: arms are {', '.join(SCENE_ARMS)}, got {ctx['arms']}")
    sess, caps = _captured_frames(ctx.scenario(ctx["scenario"]), ctx["frames"])
    try:
        views = sess.participants["renderer"].cameras.views
        rens = _scene_renderers(sess.participants["renderer"].cameras.backend, arms)
        times = {a: [[] for _ in caps] for a in arms}
        images = [{} for _ in caps]                                # the hashed arm's views, for the matcher
        for rep in range(ctx["repeats"] + 1):                     # the first compiles the shaders: not timed
            for f, (scene, light, draws) in enumerate(caps):
                for arm, r in zip(arms, rens):
                    c = time.thread_time()
                    r.set_scene(scene, light)
                    for k, pose in draws:
                        r.draw(k, pose)
                        w, h = r.views[k].size
                        img = np.empty((h, w, 4), np.uint8)
                        r.read_rgb(k, img)
                        if arm == "hashed":
                            images[f][k] = img
                    if rep:
                        times[arm][f].append(time.thread_time() - c)
    finally:
        sess.close()
    out = {}
    for arm in arms:
        per = [statistics.median(t) for t in times[arm]]
        row = {"ms per frame": 1e3 * statistics.median(per)}
        if "hashed" in arms:
            base = [statistics.median(t) for t in times["hashed"]]
            row["/ hashed"] = statistics.median(p / b for p, b in zip(per, base))
        out[arm] = row
    if "hashed" in arms:
        out.update(_matcher_times(views, images, ctx["repeats"]))
    return {f"{ctx['scenario']}: the camera views' thread CPU per frame, {len(caps)} frames": out}


def _matcher_times(views, images: list[dict], repeats: int) -> dict:
    """Per stereo camera among ``views`` (``renderer_proc.cameras.View``): its matcher's thread CPU ms per pair
    on the hashed arm's rendered pairs ``images`` (per frame: view index -> (H, W, 4) uint8), OpenCV on one thread
    as in a run (``cosim.runtime.threadpools``), the median over the frames of the least of ``repeats`` calls."""
    import statistics

    import cv2

    from perception_proc.cameras.stereo import grey, make_matcher

    cv2.setNumThreads(1)
    out = {}
    for k, v in enumerate(views):
        if "rgb" not in v.parts or getattr(v.spec, "kind", "") != "stereo_camera":
            continue
        right = next(j for j, u in enumerate(views) if u.camera == v.camera and "right" in u.parts)
        matcher, per = make_matcher(v.spec), []
        for imgs in images:
            left_g, right_g = grey(imgs[k]), grey(imgs[right])
            best = []
            for _ in range(max(repeats, 1)):
                c = time.thread_time()
                matcher.compute(left_g, right_g)
                best.append(time.thread_time() - c)
            per.append(min(best))
        out[f"{v.camera}: its matcher a pair (one thread)"] = {"ms per frame": 1e3 * statistics.median(per)}
    return out
