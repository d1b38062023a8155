"""The GL camera renderer (moderngl, headless EGL): the camera sensors' textured colour images, planar depth and
labels (docs/cameras.md).

Per view one framebuffer of renderbuffers (no textures: nothing is mipmapped or filtered, no MSAA):
attachment 0 RGBA8 colour (``shaders/camera.frag``: procedural textures from ``shaders/textures.glsl``, lit by
the sun or, at night, a work light), attachment 1 R32F planar depth (``1 / gl_FragCoord.w``, the view-space
depth itself; NaN where nothing is drawn), attachment 2 R8UI the label of the part drawn (integer: never
blended), and a depth renderbuffer for visibility. A renderer whose views read no colour (``parts``: depth
cameras only) draws with ``shaders/camera_depth.frag`` instead: its depth at attachment 0 and, where read, labels
at 1, no texture or light evaluated (the same vertex shaders: the same depth to the bit); where any view reads
colour every view is drawn textured. Parts are drawn as the LiDAR's GL renderer draws them (the
same unit meshes, instance records and grain surface, ``renderer_proc.gl.surface``), each instance carrying its
label and material; the ground slab is drawn every frame (its texture is fixed to the ground, so no cached
image). The projection flips the image vertically, so ``read_*`` fill top-down destinations directly.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from cosim.scenario.config.rendering import Lighting
from cosim.world.camera import Pinhole
from cosim.world.labels import GRAIN, GRAIN_MAT, NONE, STEEL, mesh_label, mesh_material
from cosim.world.lighting import sun_direction
from cosim.world.meshes import box_instances, cylinder_instances, pack_instances, unit_cube, unit_cylinder
from cosim.world.scene import GRAIN_COLOUR, SKY_RGBA, Scene
from renderer_proc.gl.backend import SHADER_DIR, GLResources, render_solids, upload_instances
from renderer_proc.gl.surface import Surface, mat_bytes
from renderer_proc.projection import NEAR_M, gl_projection, gl_view

__all__ = ["FAR_M", "GLCameraRenderer", "camera_fragment_source"]

#: far clipping plane of the cameras, m (everything a camera sensor reports lies well inside it)
FAR_M = 400.0
#: floats per camera instance record: the LiDAR renderer's 19 (mat4, rgb) and (label, material)
CAMERA_INSTANCE_FLOATS = 21
#: a view is drawn in horizontal strips of at most this many pixels, each finished before the next: a GL call
#: holds the Python GIL until llvmpipe is done, and a whole textured 1024 x 544 view on a loaded machine can
#: take longer than the run's liveness limit (a child's heartbeat thread needs the GIL every 0.1 s)
STRIP_PIXELS = 1 << 17
_NAN = float("nan")


def camera_fragment_source() -> str:
    """The fragment shader: ``camera.frag`` with ``textures.glsl`` inserted after its version line."""
    head, body = (SHADER_DIR / "camera.frag").read_text().split("\n", 1)
    return "\n".join([head, (SHADER_DIR / "textures.glsl").read_text(), body])


def _records(base: np.ndarray, label: np.ndarray | None, material: np.ndarray | None) -> np.ndarray:
    """Instance records (N, 21) float32: ``base`` (N, 19) and each part's (label, material)."""
    n = len(base)
    lab = np.full(n, NONE, np.float32) if label is None else np.asarray(label, np.float32)
    mat = np.full(n, STEEL, np.float32) if material is None else np.asarray(material, np.float32)
    return np.concatenate([base, lab[:, None], mat[:, None]], axis=1).astype(np.float32)


@dataclass
class _View:
    """One view's framebuffers: ``draw`` (every attachment), ``clears`` [(framebuffer, clear value)],
    ``attachment`` part -> its colour attachment in ``draw``."""

    draw: Any
    clears: list
    size: tuple[int, int]
    proj: bytes
    attachment: dict


class GLCameraRenderer(GLResources):
    """Renders :class:`Scene` frames for camera views of pinholes ``pins``. ``set_scene`` uploads a frame,
    ``draw(k, world_from_camera)`` renders view k, ``read_rgb`` / ``read_depth`` / ``read_labels`` read it out.
    ``context``: a GL context to share (the LiDAR renderer's), else one is made; ``parts``: per view the parts
    read from it (of ``rgb``, ``depth``, ``labels``; None: all of them)."""

    def __init__(self, pins: list[Pinhole], lighting: Lighting, *, context: Any = None,
                 parts: list | None = None):
        super().__init__(context)
        import moderngl  # after create_gl_context, which turns a missing moderngl into RendererUnavailable

        ctx = self.ctx
        self.pins, self.lighting = pins, lighting
        #: whether the views are drawn textured and lit (some view reads colour), else depth (and labels) only
        self.colour = parts is None or any("rgb" in p for p in parts)
        frag = camera_fragment_source() if self.colour else (SHADER_DIR / "camera_depth.frag").read_text()
        self.prog_inst = self._m(ctx.program(vertex_shader=(SHADER_DIR / "camera_inst.vert").read_text(),
                                             fragment_shader=frag))
        self.prog_hf = self._m(ctx.program(vertex_shader=(SHADER_DIR / "camera_hf.vert").read_text(),
                                           fragment_shader=frag))
        if self.colour:
            self.prog_hf["u_colour"].value = GRAIN_COLOUR
        self.prog_hf["u_tag"].value = (float(GRAIN), float(GRAIN_MAT))
        self._surface = Surface(ctx, self._m, self.prog_hf)
        self._unit: dict[str, list] = {}
        for key, (v, f) in {"box": unit_cube(), "box_open": unit_cube(open_top=True),
                            "cyl": unit_cylinder()}.items():
            self._unit[key] = self._vao(v, f)
        self._meshes: dict[str, list] = {}
        self._mesh_names: list[str] = []
        self._origin = np.zeros(3)
        self._lamp: np.ndarray | None = None
        self.views = [self._view(p, set(q) if parts is not None else {"rgb", "depth", "labels"})
                      for p, q in zip(pins, parts or pins)]
        self._sun = sun_direction(lighting)
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.disable(moderngl.BLEND)
        self._cull = moderngl.CULL_FACE

    def _vao(self, vertices: np.ndarray, faces: np.ndarray, reserve: int = 64) -> list:
        """[vertex array, instance buffer, instance count] of a unit mesh."""
        ctx = self.ctx
        vbo = self._m(ctx.buffer(vertices.astype(np.float32).tobytes()))
        ibo = self._m(ctx.buffer(faces.astype(np.int32).tobytes()))
        inst = self._m(ctx.buffer(reserve=reserve * CAMERA_INSTANCE_FLOATS * 4, dynamic=True))
        vao = self._m(ctx.vertex_array(self.prog_inst, [(vbo, "3f", "in_pos"),
                                                        (inst, "16f 3f 2f/i", "in_model", "in_colour", "in_tag")],
                                       index_buffer=ibo, index_element_size=4, skip_errors=not self.colour))
        return [vao, inst, 0]

    def _view(self, pin: Pinhole, read: set) -> _View:
        """One view's framebuffers for the parts ``read`` from it: drawn textured, colour, and depth and labels
        where either is read (the shader's outputs keep their locations; a view read for colour alone has no
        other attachment, so nothing else is cleared or written); else depth and, where read, labels; and the
        depth renderbuffer of the visibility test."""
        ctx = self.ctx
        size = (pin.width, pin.height)
        depth = self._m(ctx.depth_renderbuffer(size))
        if self.colour:
            names = ["rgb", "depth", "labels"] if read & {"depth", "labels"} else ["rgb"]
        else:
            names = ["depth"] + (["labels"] if "labels" in read else [])
        sky = tuple(SKY_RGBA) if not self.lighting.night else (*(c * self.lighting.night_ambient
                                                                 for c in SKY_RGBA[:3]), 1.0)
        make = {"rgb": lambda: ctx.renderbuffer(size, 4, dtype="f1"), "depth": lambda: ctx.renderbuffer(
            size, 1, dtype="f4"), "labels": lambda: ctx.renderbuffer(size, 1, dtype="u1")}
        clear = {"rgb": sky, "depth": (_NAN,) * 4, "labels": (0.0,) * 4}
        bufs = [self._m(make[n]()) for n in names]
        clears = [(self._m(ctx.framebuffer([b], depth if i == 0 else None)), clear[n])
                  for i, (n, b) in enumerate(zip(names, bufs))]
        return _View(self._m(ctx.framebuffer(bufs, depth)), clears, size,
                     mat_bytes(gl_projection(pin, NEAR_M, FAR_M)), {n: i for i, n in enumerate(names)})

    def _upload(self, key: str, records: np.ndarray) -> None:
        upload_instances(self._unit[key], records)

    def set_scene(self, scene: Scene, light: np.ndarray | None = None) -> None:
        """Upload one frame (instances with labels and materials, grain heights); ``light``: the work light's
        world position (3,) m when there is one."""
        self._origin = scene.heightfield.world_from_grid[:3, 3].copy()
        self._lamp = light
        b = scene.boxes
        recs = _records(box_instances(b, self._origin), b.label, b.material)
        hidden = b.hidden_top if b.hidden_top is not None else np.zeros(len(b), bool)
        self._upload("box", recs[~hidden])
        self._upload("box_open", recs[hidden])
        c = scene.cylinders
        self._upload("cyl", _records(cylinder_instances(c, self._origin), c.label, c.material))
        self._surface.upload(scene, self._origin)
        for mesh in scene.meshes:
            if mesh.name not in self._meshes:
                self._meshes[mesh.name] = self._vao(mesh.vertices, mesh.faces, reserve=1)
            rec = _records(pack_instances(mesh.world_from_mesh[None], np.array([mesh.colour]), self._origin),
                           np.array([mesh_label(mesh.name)]), np.array([mesh_material(mesh.name)]))
            self._meshes[mesh.name][1].write(rec.tobytes())
            self._meshes[mesh.name][2] = 1
        self._mesh_names = [m.name for m in scene.meshes]

    def draw(self, k: int, world_from_camera: np.ndarray) -> None:
        """Render view ``k`` at pose ``world_from_camera`` (4 x 4, camera axes) into its framebuffer."""
        v = self.views[k]
        view = gl_view(world_from_camera)
        view[:3, 3] += view[:3, :3] @ self._origin          # view @ world_from_local, in float64
        self.ctx.front_face = "cw" if np.linalg.det(view[:3, :3]) > 0.0 else "ccw"
        lt = self.lighting
        sun_share = 0.0 if lt.night else 1.0 - lt.ambient
        lamp = (view[:3, :3] @ self._lamp + view[:3, 3] - view[:3, :3] @ self._origin
                if self._lamp is not None else np.zeros(3))
        for prog in (self.prog_inst, self.prog_hf):
            prog["u_view"].write(mat_bytes(view))
            prog["u_proj"].write(v.proj)
            if not self.colour:                         # depth only: nothing lit
                continue
            prog["u_origin"].value = tuple(self._origin)
            prog["u_sun"].value = tuple(view[:3, :3] @ self._sun)
            prog["u_sun_share"].value = sun_share
            prog["u_ambient"].value = lt.night_ambient if lt.night else lt.ambient
            prog["u_lamp"].value = tuple(lamp)
            prog["u_lamp_intensity"].value = lt.work_light.intensity if (lt.work_light and self._lamp is not None) \
                else 0.0
        for fbo, colour in v.clears:
            fbo.clear(*colour, depth=1.0)
        v.draw.use()
        w, h = v.size
        rows = max(1, STRIP_PIXELS // w)
        for y0 in range(0, h, rows):
            v.draw.scissor = (0, y0, w, min(rows, h - y0))
            self._draw_parts()
            self.ctx.finish()                           # the strip done: the GIL is free between strips
        v.draw.scissor = None

    def _draw_parts(self) -> None:
        """Draw every part into the framebuffer in use (solids culled, meshes two-sided)."""
        self.ctx.enable(self._cull)
        render_solids(self._unit, self._surface)
        self.ctx.disable(self._cull)
        for name in self._mesh_names:
            self._meshes[name][0].render(instances=1)

    def _check(self, k: int, out: np.ndarray, shape: tuple, dtype) -> None:
        if out.shape != shape or out.dtype != np.dtype(dtype) or not out.flags.c_contiguous:
            raise ValueError(f"view {k}: destination must be C-contiguous {shape} {np.dtype(dtype)}, got "
                             f"{out.shape} {out.dtype}")

    def _attachment(self, k: int, part: str) -> int:
        """The colour attachment of view ``k``'s ``part``; ValueError where the view does not draw it."""
        try:
            return self.views[k].attachment[part]
        except KeyError:
            raise ValueError(f"view {k} draws no {part} (it draws {', '.join(self.views[k].attachment)})") from None

    def read_rgb(self, k: int, out: np.ndarray) -> None:
        """View k's colour image into ``out`` (H, W, 4) uint8 in place."""
        v = self.views[k]
        self._check(k, out, (v.size[1], v.size[0], 4), np.uint8)
        v.draw.read_into(out, components=4, attachment=self._attachment(k, "rgb"), alignment=1, dtype="f1")

    def read_depth(self, k: int, out: np.ndarray) -> None:
        """View k's planar depth into ``out`` (H, W) float32 m (NaN where nothing is drawn) in place."""
        v = self.views[k]
        self._check(k, out, (v.size[1], v.size[0]), np.float32)
        v.draw.read_into(out, components=1, attachment=self._attachment(k, "depth"), alignment=1, dtype="f4")

    def read_labels(self, k: int, out: np.ndarray) -> None:
        """View k's labels into ``out`` (H, W) uint8 in place."""
        v = self.views[k]
        self._check(k, out, (v.size[1], v.size[0]), np.uint8)
        v.draw.read_into(out, components=1, attachment=self._attachment(k, "labels"), alignment=1, dtype="u1")

