"""The OpenGL renderer (moderngl, headless EGL): the paper's Unreal side.

Importing this module does not touch GL: moderngl is imported inside :func:`create_gl_context`. Per camera it
owns one framebuffer of renderbuffers (no textures, so nothing can mipmap or filter them, and no MSAA):

* attachment 0: RGBA8UI, the encoded depth bytes written by ``shaders/encode.frag``;
* optional RGBA8 shaded image (``rgb``) and R32F planar depth (``float_depth``, NaN where invalid);
* a depth renderbuffer for visibility only (the encoded value comes from view-space z, never from it).

The image is flipped in the projection (``renderer_proc.projection``), so ``read_into`` fills a top-down
(H, W, 4) destination, e.g. a shared-memory view, directly.

Throughput on llvmpipe (bench/HISTORY.md, "Renderer"): the cost is rasterisation, per 4 x 4 pixel block each
triangle touches, hidden or not. So the grain surface is drawn with its flat blocks merged
(``renderer_proc.gl.hfmesh``), box faces that other parts always cover are skipped (``Boxes.hidden_top``), the
ground slab, which fills every image, is drawn once per camera and copied into each frame while the camera's
pose relative to the ground plane is unchanged (:meth:`GLRenderer._ground_key`), and the encoding shader reads
no varying in the depth-only pass.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from cosim.errors import RendererUnavailable
from cosim.scenario.config.sensing import Codec
from cosim.world.camera import Rig
from cosim.world.geometry import invert
from cosim.world.meshes import (
    INSTANCE_FLOATS,
    box_instances,
    cylinder_instances,
    pack_instances,
    unit_cube,
    unit_cylinder,
)
from cosim.world.scene import GRAIN_COLOUR, SKY_RGBA, SUN_WORLD, Scene
from renderer_proc.codec import BYTE_MAX, CM_PER_M
from renderer_proc.gl.surface import Surface
from renderer_proc.gl.surface import mat_bytes as _mat
from renderer_proc.projection import NEAR_M, far_plane_m, gl_projection, gl_view

__all__ = ["GL_REQUIRE", "SHADER_DIR", "GLResources", "GLRenderer", "create_gl_context", "render_solids", "set_uniform",
           "upload_instances"]

#: directory of the GLSL sources
SHADER_DIR = Path(__file__).parents[1] / "shaders"
#: minimum OpenGL version (x 100)
GL_REQUIRE = 330
_FALLBACK_HINT = "Run with --renderer mock (scenario key renderer: mock) to use the numpy ray caster instead."


def create_gl_context(backend: str = "egl") -> Any:
    """A standalone headless moderngl context; :class:`RendererUnavailable` naming the cause if none."""
    try:
        import moderngl
    except ImportError as exc:  # pragma: no cover - moderngl is a dependency
        raise RendererUnavailable(f"moderngl cannot be imported ({exc}). {_FALLBACK_HINT}") from exc
    try:
        return moderngl.create_context(standalone=True, backend=backend, require=GL_REQUIRE)
    except Exception as exc:  # moderngl raises plain Exception subclasses for every driver failure
        raise RendererUnavailable(
            f"no OpenGL >= {GL_REQUIRE / 100:.1f} context could be made (standalone, backend {backend!r}): "
            f"{exc}. {_FALLBACK_HINT}") from exc


def _source(name: str) -> str:
    return (SHADER_DIR / name).read_text()


def _fragment_source(rgb: bool, float_depth: bool, mishandled: bool) -> str:
    head, body = _source("encode.frag").split("\n", 1)
    defines = ["#define MISHANDLED_GAMMA"] if mishandled else []
    loc = 1
    if rgb:
        defines.append(f"#define OUT_RGB {loc}")
        loc += 1
    if float_depth:
        defines.append(f"#define OUT_ZF {loc}")
    return "\n".join([head, *defines, _source("codec.glsl"), body])


def render_solids(units: dict, surface: Surface) -> None:
    """Draw the instanced cylinders (stream, auger), the grain surface and the boxes, open then closed, in that
    order (roughly front to back: early depth rejection skips hidden shading); ``units`` maps a unit name to its
    (vertex array, instance buffer, instance count)."""
    vao, _, n = units["cyl"]
    if n:
        vao.render(instances=n)
    surface.render()
    for name in ("box_open", "box"):
        vao, _, n = units[name]
        if n:
            vao.render(instances=n)


@dataclass
class _Buffers:
    """A set of renderbuffers: ``draw`` has every attachment; ``clears`` pairs a framebuffer of each attachment
    (the first with the depth buffer) with its clear colour (integer, float and unorm are cleared separately)."""

    draw: Any
    clears: list


@dataclass
class GroundImage:
    """The ground slab drawn alone (``buffers``, made on first use), kept while the ``key`` it was drawn for holds
    (the sensor's pose to the ground plane: a vehicle driving and turning on flat ground keeps it) and copied
    into each frame: the copy (colour and depth, nearest, same size and format: the bytes themselves) costs what a
    clear costs, the slab's rasterisation (most of the image) is skipped."""

    buffers: _Buffers | None = None
    key: tuple | None = None


def begin_frame(ctx: Any, frame: _Buffers, ground: GroundImage, key: tuple | None, make: Callable[[], _Buffers],
                draw_ground: Callable[[], None]) -> None:
    """Start drawing ``frame``: a copy of the cached ground image when ``key`` is not None (drawn first, into
    buffers from ``make``, by ``draw_ground``, when the key changed), else a clear; ``frame.draw`` is then in
    use. The caller draws the ground itself when ``key`` is None."""
    if key is not None:
        if ground.buffers is None:
            ground.buffers = make()
        if key != ground.key:
            for fbo, colour in ground.buffers.clears:
                fbo.clear(*colour, depth=1.0)
            ground.buffers.draw.use()
            draw_ground()
            ground.key = key
        for (dst, _), (src, _) in zip(frame.clears, ground.buffers.clears):
            ctx.copy_framebuffer(dst, src)
    else:
        for fbo, colour in frame.clears:
            fbo.clear(*colour, depth=1.0)
    frame.draw.use()


@dataclass
class _Target:
    """One camera's framebuffers (``frame``), its projection, the farthest a drawn point can be from the camera
    (``reach_m``: far plane times the corner ray's length per unit planar depth), and its cached ground image."""

    frame: _Buffers
    size: tuple[int, int]
    proj: bytes
    reach_m: float
    rgb_attachment: int
    zf_attachment: int
    ground: GroundImage = field(default_factory=GroundImage)


def upload_instances(unit: list, records: np.ndarray) -> None:
    """Write a frame's instance ``records`` (N, F) into a draw unit ``[vao, buffer, count]`` (float32, the buffer
    grown when they do not fit) and set its instance count to N."""
    data = np.ascontiguousarray(records, dtype=np.float32)
    if data.nbytes > unit[1].size:
        unit[1].orphan(data.nbytes)
    if data.nbytes:
        unit[1].write(data)
    unit[2] = len(data)


class GLResources:
    """The renderers' common base: a GL context, made here (``context`` None) or lent, every GL object made in it
    through :meth:`_m` (:meth:`close` releases the context when it is ours, else those objects)."""

    def __init__(self, context: Any = None):
        self._own_ctx = context is None
        self._made: list = []
        self.ctx = context if context is not None else create_gl_context()

    def make_current(self) -> None:
        """Make this renderer's context the thread's current one (moderngl draws into whichever context is
        current: several renderers in one thread, e.g. in-process simulations side by side, each make theirs
        current when a frame starts, ~7 us)."""
        self.ctx.__enter__()

    def _m(self, obj):
        """Remember a GL object made here, to release it when the context is not ours."""
        self._made.append(obj)
        return obj

    def close(self) -> None:
        """Release the GL context (when this renderer made it), else every object made in it."""
        if self.ctx is None:
            return
        if self._own_ctx:
            self.ctx.release()
        else:
            for obj in reversed(self._made):
                obj.release()
        self._made.clear()
        self.ctx = None


def set_uniform(prog: Any, name: str, value) -> None:
    """Set uniform ``name`` of ``prog`` where the program keeps it (the compiler drops unused ones). ``prog.get`` is
    a dict look-up; ``name in prog`` would walk every member."""
    uniform = prog.get(name, None)
    if uniform is not None:
        uniform.value = value


class GLRenderer(GLResources):
    """Renders :class:`Scene` frames for every camera of ``rig``. ``set_scene`` uploads a frame (instance
    buffers, grain heights), ``draw(k, world_from_camera)`` renders camera k, ``read_*`` read it out."""

    def __init__(self, rig: Rig, codec: Codec, *, rgb: bool = False, float_depth: bool = False,
                 context: Any = None):
        self.rig, self.codec, self.rgb, self.float_depth = rig, codec, rgb, float_depth
        super().__init__(context)
        ctx = self.ctx
        import moderngl  # after create_gl_context, which turns a missing moderngl into RendererUnavailable

        frag = _fragment_source(rgb, float_depth, codec.gamma_mode == "mishandled")
        self.prog_inst = self._m(ctx.program(vertex_shader=_source("instanced.vert"), fragment_shader=frag))
        self.prog_hf = self._m(ctx.program(vertex_shader=_source("heightfield.vert"), fragment_shader=frag))
        for prog in (self.prog_inst, self.prog_hf):
            set_uniform(prog, "u_q_per_m", CM_PER_M / codec.beta_cm)
            set_uniform(prog, "u_q_max", codec.alpha_cm / codec.beta_cm)
            set_uniform(prog, "u_r_per_period", BYTE_MAX * codec.beta_cm / codec.alpha_cm)
            set_uniform(prog, "u_gamma", codec.gamma)
        set_uniform(self.prog_hf, "u_colour", GRAIN_COLOUR)
        self._surface = Surface(ctx, self._m, self.prog_hf)
        self._unit = {}
        units = {"box": unit_cube(), "box_open": unit_cube(open_top=True), "ground": unit_cube(),
                 "cyl": unit_cylinder()}
        for key, (v, f) in units.items():
            vbo, ibo = self._m(ctx.buffer(v.tobytes())), self._m(ctx.buffer(f.tobytes()))
            inst = self._m(ctx.buffer(reserve=64 * INSTANCE_FLOATS * 4, dynamic=True))
            vao = self._m(ctx.vertex_array(self.prog_inst, [(vbo, "3f", "in_pos"), self._instance_format(inst)],
                                           index_buffer=ibo, index_element_size=4))
            self._unit[key] = [vao, inst, 0]
        self._meshes: dict[str, list] = {}
        self._mesh_names: list[str] = []
        self._origin = np.zeros(3)
        self._ground: tuple[np.ndarray, np.ndarray, tuple] | None = None
        far = far_plane_m(codec.max_depth_m)
        self.targets = [self._target(c.intrinsics, far) for c in rig.cameras]
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.disable(moderngl.BLEND)
        self._cull = moderngl.CULL_FACE

    def _instance_format(self, buf) -> tuple:
        """Instance attribute binding; the colour is skipped when the shader has optimised it out (no rgb)."""
        if "in_colour" in self.prog_inst:
            return (buf, "16f 3f/i", "in_model", "in_colour")
        return (buf, "16f 12x/i", "in_model")

    def _buffers(self, size: tuple[int, int]) -> _Buffers:
        ctx = self.ctx
        depth = self._m(ctx.depth_renderbuffer(size))
        enc = self._m(ctx.renderbuffer(size, 4, dtype="u1"))
        atts, clears = [enc], [(self._m(ctx.framebuffer([enc], depth)), (0.0, 0.0, 0.0, 0.0))]
        if self.rgb:
            atts.append(self._m(ctx.renderbuffer(size, 4, dtype="f1")))
            clears.append((self._m(ctx.framebuffer([atts[-1]])), SKY_RGBA))
        if self.float_depth:
            atts.append(self._m(ctx.renderbuffer(size, 1, dtype="f4")))
            clears.append((self._m(ctx.framebuffer([atts[-1]])), (float("nan"),) * 4))
        return _Buffers(self._m(ctx.framebuffer(atts, depth)), clears)

    def _target(self, cam, far: float) -> _Target:
        size = (cam.width, cam.height)
        corner = math.hypot(1.0, cam.width / (2.0 * cam.f), cam.height / (2.0 * cam.f))
        return _Target(self._buffers(size), size, _mat(gl_projection(cam, NEAR_M, far)), far * corner,
                       1 if self.rgb else -1, (2 if self.rgb else 1) if self.float_depth else -1)

    def _upload(self, key: str, records: np.ndarray) -> None:
        upload_instances(self._unit[key], records)

    def _mesh(self, mesh) -> None:
        if mesh.name not in self._meshes:
            vbo = self._m(self.ctx.buffer(mesh.vertices.astype(np.float32).tobytes()))
            ibo = self._m(self.ctx.buffer(mesh.faces.astype(np.int32).tobytes()))
            inst = self._m(self.ctx.buffer(reserve=INSTANCE_FLOATS * 4, dynamic=True))
            vao = self._m(self.ctx.vertex_array(self.prog_inst, [(vbo, "3f", "in_pos"), self._instance_format(inst)],
                                                index_buffer=ibo, index_element_size=4))
            self._meshes[mesh.name] = [vao, inst]
        self._meshes[mesh.name][1].write(pack_instances(mesh.world_from_mesh[None], np.array([mesh.colour]),
                                                           self._origin))

    def set_scene(self, scene: Scene) -> None:
        """Upload one frame: box / cylinder instance records (boxes with a hidden top face drawn without it),
        mesh poses, the grain heights (a buffer write; the triangle list only when its flat blocks change)."""
        self.make_current()
        # GPU coordinates are relative to the cart grid origin (float64 here, float32 there)
        self._origin = scene.heightfield.world_from_grid[:3, 3].copy()
        boxes = box_instances(scene.boxes, self._origin)
        hidden = scene.boxes.hidden_top
        if hidden is None:
            hidden = np.zeros(len(boxes), dtype=bool)
        ground = np.zeros(len(boxes), dtype=bool)
        self._ground = None
        if scene.ground_box is not None:
            g = scene.ground_box
            ground[g] = True
            self._ground = (scene.boxes.world_from_box[g], scene.boxes.half_extents[g],
                            tuple(scene.boxes.colour[g].tolist()))
        self._upload("box", boxes[~hidden & ~ground])
        self._upload("box_open", boxes[hidden & ~ground])
        self._upload("ground", boxes[ground])
        self._upload("cyl", cylinder_instances(scene.cylinders, self._origin))
        self._surface.upload(scene, self._origin)
        for mesh in scene.meshes:
            self._mesh(mesh)
        self._mesh_names = [m.name for m in scene.meshes]

    def _ground_key(self, t: _Target, world_from_camera: np.ndarray) -> tuple | None:
        """What the ground slab looks like from this camera, or None when the cached image cannot be used.

        Seen from a camera whose farthest visible point (``reach_m``) stays inside the slab's top face, the slab
        is an unbounded plane (and the plane below it): its image depends only on the camera's pose modulo
        turns about the slab's z axis and shifts along x and y, i.e. on the third row of slab_from_camera (and
        the slab's thickness and colour). A camera on a vehicle keeps that row bit for bit while the vehicle
        drives and turns on the ground, so the image is drawn once and copied into each frame."""
        if self._ground is None:
            return None
        world_from_slab, half, colour = self._ground
        slab_from_camera = invert(world_from_slab) @ world_from_camera
        x, y = slab_from_camera[0, 3], slab_from_camera[1, 3]
        if abs(x) + t.reach_m > half[0] or abs(y) + t.reach_m > half[1]:
            return None
        return (*slab_from_camera[2].tolist(), float(half[2]), colour)

    def _draw_ground(self) -> None:
        vao, _, n = self._unit["ground"]
        if n:
            vao.render(instances=n)

    def draw(self, k: int, world_from_camera: np.ndarray) -> None:
        """Render camera ``k`` of the rig at pose ``world_from_camera`` (4 x 4) into its framebuffer."""
        t = self.targets[k]
        view = gl_view(world_from_camera)
        view[:3, 3] += view[:3, :3] @ self._origin          # view @ world_from_local, in float64
        # the projection flips the image vertically, which turns counter-clockwise (outward) faces clockwise;
        # a pose with right-handed camera axes (det +1, e.g. in tests) mirrors them back
        self.ctx.front_face = "cw" if np.linalg.det(view[:3, :3]) > 0.0 else "ccw"
        for prog in (self.prog_inst, self.prog_hf):
            prog["u_view"].write(_mat(view))
            prog["u_proj"].write(t.proj)
            set_uniform(prog, "u_light", tuple(view[:3, :3] @ SUN_WORLD))
        # closed, outward-wound solids and the height field (seen from above only) cull their back faces;
        # mesh files have unknown winding and are drawn two-sided
        self.ctx.enable(self._cull)
        key = self._ground_key(t, world_from_camera)
        begin_frame(self.ctx, t.frame, t.ground, key, lambda: self._buffers(t.size), self._draw_ground)
        # drawn roughly front to back (stream and auger, grain, boxes, the ground slab last when not cached) so
        # that early depth rejection skips the shading of hidden fragments; llvmpipe still rasterises and
        # depth-tests them (a hidden layer costs about 3/4 of a visible one), hence the skipped hidden faces
        render_solids(self._unit, self._surface)
        if key is None:
            self._draw_ground()
        self.ctx.disable(self._cull)
        for name in self._mesh_names:
            self._meshes[name][0].render(instances=1)

    @staticmethod
    def _check(out: np.ndarray, shape: tuple, dtype) -> None:
        if out.shape != shape or out.dtype != np.dtype(dtype) or not out.flags.c_contiguous:
            raise ValueError(f"destination must be C-contiguous {shape} {np.dtype(dtype)}, got {out.shape} "
                             f"{out.dtype} (contiguous: {out.flags.c_contiguous})")

    def read_depth(self, k: int, out: np.ndarray) -> None:
        """Read camera k's encoded bytes into ``out`` (H, W, 4) uint8 in place (e.g. a shared-memory view)."""
        t = self.targets[k]
        self._check(out, (t.size[1], t.size[0], 4), np.uint8)
        t.frame.draw.read_into(out, components=4, attachment=0, alignment=1, dtype="u1")

    def read_rgb(self, k: int, out: np.ndarray) -> None:
        """Read camera k's shaded image into ``out`` (H, W, 4) uint8 in place."""
        t = self.targets[k]
        if t.rgb_attachment < 0:
            raise ValueError("this renderer was made without the rgb output")
        self._check(out, (t.size[1], t.size[0], 4), np.uint8)
        t.frame.draw.read_into(out, components=4, attachment=t.rgb_attachment, alignment=1, dtype="f1")

    def read_zf(self, k: int, out: np.ndarray) -> None:
        """Read camera k's planar depth into ``out`` (H, W) float32 m (NaN invalid) in place."""
        t = self.targets[k]
        if t.zf_attachment < 0:
            raise ValueError("this renderer was made without the float depth output")
        self._check(out, (t.size[1], t.size[0]), np.float32)
        t.frame.draw.read_into(out, components=1, attachment=t.zf_attachment, alignment=1, dtype="f4")

