"""The GL beam-native renderer: the scene drawn from the LiDAR origin into one pixel per beam (docs/lidar.md).

``sensor.method: beam_native`` with ``renderer: gl``. The target's pixel (col, row) is the beam of azimuth
column ``col`` and elevation row ``row`` of a grid or honeycomb pattern (``cosim.world.beamtarget``). Two paths,
both exact per beam:

* triangles (the grain surface, mesh files): the vertex shader (``shaders/beam_instanced.vert``,
  ``shaders/beam_heightfield.vert``) puts vertices in the LiDAR frame relative to its origin (float64 pose on
  the CPU, float32 offsets on the GPU) with their azimuth and elevation; the geometry shader
  (``shaders/beam.geom``) bounds each triangle in angle space, conservatively (corners, each edge's extreme
  elevation, a pole it holds, the back seam), and emits the rectangle of beam pixels inside the bound with the
  triangle as flat outputs; the fragment shader (``shaders/beam.frag``) intersects its own beam (a texture of
  the pattern's directions) with the triangle, Moller-Trumbore from the origin, discards a miss (exact coverage
  at silhouettes) and writes the range with Eqs 1-2 and depth t / far for the nearest hit; the grain surface's
  triangles go in pairs (``renderer_proc/gl/surface.py``, ``shaders/beam_quad.*``): a quad's two triangles
  bounded at once and tested in one fragment, the nearer hit kept;
* convex solids (boxes; cylinders as the prisms the ray caster uses): one point per instance
  (``shaders/solid.*``), a box bounded in slices along its longest edge (up to :func:`max_rects` rectangles;
  one with a covered top, ``Boxes.hidden_top``, seen from above by its front side faces), a prism whole, and
  each beam clipped against the whole solid's slabs or planes.

There is no projection, so no near plane, no stitching, no parallax and no resample, and a 360 deg field is one
target (rectangles across the back seam are emitted twice). The ground slab's top face is the ground plane
exactly; its image is cached while the LiDAR keeps its pose to the ground (:func:`ground_key`). CSV patterns have
no grid of angles to bound in; the participant gives them the exact ray cast of
:class:`renderer_proc.mock.beam.MockBeamRenderer` instead.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from cosim.scenario.config.sensing import Codec
from cosim.world.beamtarget import BeamLayout
from cosim.world.labels import TERRAIN_MESH_PREFIX
from cosim.world.meshes import CYLINDER_SIDES, INSTANCE_FLOATS, box_instances, cylinder_instances, pack_instances
from cosim.world.scene import GRAIN_COLOUR, SKY_RGBA, SUN_WORLD, Scene
from renderer_proc.codec import BYTE_MAX, CM_PER_M
from renderer_proc.gl.backend import (
    SHADER_DIR,
    GLResources,
    GroundImage,
    _Buffers,
    begin_frame,
    set_uniform,
    upload_instances,
)
from renderer_proc.gl.meshcull import pattern_planes, visible_faces
from renderer_proc.gl.surface import Surface
from renderer_proc.gl.surface import mat_bytes as _mat
from renderer_proc.mock.beam import check_target
from renderer_proc.projection import far_plane_m

__all__ = ["ANGLE_SLACK_RAD", "EDGE_SLACK", "ROW_BINS", "GLBeamRenderer", "cpu_rasteriser", "ground_key", "max_rects",
           "row_bounds", "slicing_pays"]

#: slack of every angular bound in the geometry shader, rad (every angle there is an atan: llvmpipe's is within
#: 3.5e-6 rad, its asin off by up to 3.9e-4 rad, so none is used; a beam pitch is ~5e-3 rad): only widens the
#: rectangles, the fragment test decides
ANGLE_SLACK_RAD = 1e-4
#: the GLSL snippet of the target's angle coordinates (vertex and geometry shaders)
ANGLES = "beam_angles.glsl"
#: the GLSL snippets of the target's angle bounds (geometry shaders) and of the codec (fragment shaders)
BOUNDS = "beam_bounds.glsl"
CODEC = "codec.glsl"
#: elevation bins of the geometry shader's row table (row_bounds)
ROW_BINS = 4096
#: GL_MAX_GEOMETRY_TOTAL_OUTPUT_COMPONENTS guaranteed by OpenGL 3.3 (llvmpipe's too): max_vertices times the
#: components of one emitted vertex may not exceed it
GEOMETRY_OUTPUT_COMPONENTS = 1024
#: components of one vertex solid.geom emits: gl_Position, unit_from_sensor (mat3), origin (vec3), colour (rgb)
SOLID_VERTEX_COMPONENTS = 4 + 9 + 3
#: the colour's components, emitted with the shaded output only
SOLID_RGB_COMPONENTS = 3
#: cost of bounding one more slice of a solid in solid.geom, in fragments shaded (llvmpipe): a slice pays off
#: when it saves more
SLICE_COST_PX = 100.0
#: rectangles of the prisms' (cylinders') geometry shader: 2, unsliced (see docs/lidar.md: slicing the auger tube
#: saves fewer fragments than the longer geometry shader costs on the 30 prisms of the default scene)
PRISM_RECTS = 2
#: rectangles of the boxes' geometry shader where no CPU rasteriser draws (:func:`slicing_pays`): unsliced
UNSLICED_RECTS = 2
#: GL_RENDERER substrings of the CPU rasterisers (Mesa's), where fragments are dear and slicing the boxes pays
CPU_RASTERISERS = ("llvmpipe", "softpipe", "swr")
#: vertices of one rectangle of beam pixels (a triangle strip)
RECT_VERTICES = 4
#: inclusive slack of the fragment's inside-triangle test, barycentric: closes float32 cracks on shared edges
#: (a beam this close to a silhouette edge, 2e-6 of the triangle's size, is counted as a hit)
EDGE_SLACK = 2e-6


def row_bounds(row_el: np.ndarray, bins: int = ROW_BINS) -> tuple[float, float, np.ndarray]:
    """The geometry shader's elevation-to-rows table: ``row_el`` (rows,) rad, falling (the target's row
    elevations). Elevations from ``base`` up are cut into ``bins`` equal bins (``per_rad`` bins per rad) that
    span the rows with :data:`ANGLE_SLACK_RAD` to spare; returns (base, per_rad, table (bins, 2) float32) with,
    per bin, the first row whose elevation is at most the bin's top edge and the last row whose elevation is
    at least its bottom edge: the rows of any elevation interval are within [table[k_hi, 0], table[k_lo, 1]]
    of the bins k_lo, k_hi of its ends (conservative; exact row counts fit float32)."""
    el = np.asarray(row_el, np.float64)
    base = float(el[-1]) - 2.0 * ANGLE_SLACK_RAD
    span = float(el[0]) + 2.0 * ANGLE_SLACK_RAD - base
    edges = base + span * np.arange(bins + 1) / bins
    asc = el[::-1]                                                  # rising, for searchsorted
    above_top = len(el) - np.searchsorted(asc, edges[1:], side="right")      # rows with el > top edge
    at_or_above_bottom = len(el) - np.searchsorted(asc, edges[:-1], side="left")
    table = np.stack([above_top, at_or_above_bottom - 1], axis=1).astype(np.float32)
    return base, bins / span, np.ascontiguousarray(table)


def max_rects(rgb: bool) -> int:
    """Rectangles solid.geom may emit for one solid (its slices, two for one across the back seam): as many as
    fit the geometry shader's output limit (:data:`GEOMETRY_OUTPUT_COMPONENTS`); 16 without the shaded output,
    13 with it."""
    components = SOLID_VERTEX_COMPONENTS + (SOLID_RGB_COMPONENTS if rgb else 0)
    return GEOMETRY_OUTPUT_COMPONENTS // components // RECT_VERTICES


def cpu_rasteriser(gl_renderer: str) -> bool:
    """Whether the GL implementation named ``gl_renderer`` (GL_RENDERER) rasterises on the CPU
    (:data:`CPU_RASTERISERS`): fragments are dear there, and its float32 arithmetic and interpolation are IEEE."""
    name = gl_renderer.lower()
    return any(cpu in name for cpu in CPU_RASTERISERS)


def slicing_pays(gl_renderer: str) -> bool:
    """Whether the boxes are bounded in slices (up to :func:`max_rects` rectangles) on the GL implementation named
    ``gl_renderer`` (GL_RENDERER): on a CPU rasteriser, where a fragment costs more than bounding one more slice;
    a GPU shades the few thousand extra fragments for nothing, and NVIDIA's GLSL compiler (driver 580) crashes
    on the slicing loop. The image is the same either way (solid.frag clips every beam against the whole solid)."""
    return cpu_rasteriser(gl_renderer)


def _solid_geom(defines: tuple[str, ...], rects: int) -> str:
    """solid.geom emitting at most ``rects`` rectangles per solid (2: unsliced)."""
    return _assemble("solid.geom", ANGLES, BOUNDS, defines=defines + (
        f"#define MAX_RECTS {rects}", f"#define MAX_VERTICES {rects * RECT_VERTICES}",
        f"#define SLICE_COST_PX {SLICE_COST_PX:.1f}"))


def _src(name: str) -> str:
    return (SHADER_DIR / name).read_text()


def _assemble(name: str, *parts: str, defines: tuple[str, ...] = ()) -> str:
    """Shader ``name`` with ``defines`` and the shared snippets ``parts`` inserted after its #version line."""
    head, body = _src(name).split("\n", 1)
    return "\n".join([head, *defines, *(_src(p) for p in parts), body])


def ground_key(world_from_slab: np.ndarray, half: np.ndarray, world_from_sensor: np.ndarray,
               reach_m: float) -> tuple | None:
    """What the ground slab looks like from the LiDAR, or None when a cached image cannot be used.

    While every beam's reach (``reach_m``) stays inside the slab's top face, the slab is an unbounded plane
    (and the plane below it): the range along each beam depends only on the third row of slab_from_sensor (the
    sensor axes' z components and its height) and the slab's thickness, not on turns about the slab's z axis
    or shifts along x and y (as ``renderer_proc.gl.backend.GLRenderer._ground_key`` for cameras)."""
    slab_from_sensor = np.linalg.inv(world_from_slab) @ world_from_sensor
    x, y = slab_from_sensor[0, 3], slab_from_sensor[1, 3]
    if abs(x) + reach_m > half[0] or abs(y) + reach_m > half[1]:
        return None
    return (*slab_from_sensor[2].tolist(), float(half[2]))


class GLBeamRenderer(GLResources):
    """Beam-native GL renderer of a gridded :class:`BeamLayout`: ``set_scene``, ``draw(0, world_from_sensor)``,
    ``read_depth(0, out)``, ``read_rgb(0, out)``, ``close`` (the renderer interface with one target).
    ``surface_quads`` False draws the grain surface as single triangles, the path before the quads (for
    side-by-side measurement, ``python bench/run.py beam_surface``). ``cull_terrain`` False draws every triangle
    of the terrain's patch, not only those a beam may meet (``renderer_proc/gl/meshcull.py``; the same image)."""

    def __init__(self, layout: BeamLayout, codec: Codec, *, rgb: bool = False, context: Any = None,
                 surface_quads: bool = True, cull_terrain: bool = True):
        if not layout.gridded:
            raise ValueError("the GL beam-native renderer needs a grid or honeycomb pattern (a CSV table has no "
                             "angle grid); use the exact ray cast (renderer_proc.mock.beam.MockBeamRenderer)")
        self.layout, self.codec, self.rgb = layout, codec, rgb
        super().__init__(context)
        import moderngl  # after create_gl_context, which turns a missing moderngl into RendererUnavailable

        ctx = self.ctx
        defines = (("#define MISHANDLED_GAMMA",) if codec.gamma_mode == "mishandled" else ()) + \
            (("#define OUT_RGB 1",) if rgb else ())
        frag = _assemble("beam.frag", CODEC, defines=defines)
        geom = _assemble("beam.geom", ANGLES, BOUNDS)
        # triangles (the grain surface, mesh files): bounded per triangle, Moller-Trumbore per beam
        self.prog_inst = self._m(ctx.program(vertex_shader=_assemble("beam_instanced.vert", ANGLES),
                                             geometry_shader=geom, fragment_shader=frag))
        self.prog_hf = self._m(ctx.program(vertex_shader=_assemble("beam_heightfield.vert", ANGLES),
                                           geometry_shader=geom, fragment_shader=frag))
        # convex solids (boxes, cylinders as prisms): one point per instance, boxes bounded in slices (on a CPU
        # rasteriser), prisms whole, each beam clipped against the whole solid
        box_rects = max_rects(rgb) if slicing_pays(ctx.info["GL_RENDERER"]) else UNSLICED_RECTS
        self.prog_box = self._m(ctx.program(vertex_shader=_src("solid.vert"),
                                            geometry_shader=_solid_geom(defines, box_rects),
                                            fragment_shader=_assemble("solid.frag", CODEC, defines=defines)))
        self.prog_prism = self._m(ctx.program(
            vertex_shader=_src("solid.vert"), geometry_shader=_solid_geom(defines, PRISM_RECTS),
            fragment_shader=_assemble("solid.frag", CODEC, defines=defines + (f"#define PRISM_SIDES {CYLINDER_SIDES}",))))
        # the grain surface as quads (SurfaceMesh.quads): two triangles bounded and tested at once (gl/surface.py)
        self.prog_quad = self._m(ctx.program(vertex_shader=_assemble("beam_heightfield.vert", ANGLES),
                                             geometry_shader=_assemble("beam_quad.geom", ANGLES, BOUNDS),
                                             fragment_shader=_assemble("beam_quad.frag", CODEC, defines=defines)))
        self._surface = Surface(ctx, self._m, self.prog_quad if surface_quads else self.prog_hf, quads=surface_quads)
        self._progs = (self.prog_inst, self.prog_hf, self.prog_box, self.prog_prism, self.prog_quad)
        rows, cols = layout.shape
        az = layout.azimuth[:cols]
        centre = 0.5 * float(az[0] + az[-1])
        self.far_m = far_plane_m(codec.max_depth_m)
        values = {"u_q_per_m": CM_PER_M / codec.beta_cm, "u_q_max": codec.alpha_cm / codec.beta_cm,
                  "u_r_per_period": BYTE_MAX * codec.beta_cm / codec.alpha_cm, "u_gamma": codec.gamma,
                  "u_az_centre": centre, "u_az_first": float(az[0]) - centre,
                  "u_daz": float(az[0] - az[1]) if cols > 1 else 1.0, "u_size": (cols, rows),
                  "u_margin": ANGLE_SLACK_RAD, "u_far": self.far_m, "u_edge": EDGE_SLACK,
                  "u_rows": 0, "u_dirs": 1, "u_colour": GRAIN_COLOUR}
        row_el = layout.elevation[::cols]
        base, per_rad, table = row_bounds(row_el)
        values["u_bins"] = (base, per_rad)
        values["u_pitch"] = (values["u_daz"], float(row_el[0] - row_el[-1]) / (rows - 1) if rows > 1 else 1.0)
        for prog in self._progs:
            for name, value in values.items():
                set_uniform(prog, name, value)
        set_uniform(self.prog_box, "u_z0", -1.0)                      # the unit cube's hull: itself
        set_uniform(self.prog_prism, "u_z0", 0.0)                     # the unit prism's hull: [-1, 1]^2 x [0, 1]
        self._row_tex = self._m(ctx.texture((len(table), 1), 2, table.tobytes(), dtype="f4"))
        self._dir_tex = self._m(ctx.texture((cols, rows), 3, layout.direction_image().tobytes(), dtype="f4"))
        for tex in (self._row_tex, self._dir_tex):
            tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self._frame = self._buffers()
        self._ground_img = GroundImage()                  # the ground alone, kept while its key holds
        self._ground: tuple[np.ndarray, np.ndarray] | None = None
        self._units = {key: self._solids(prog) for key, prog in (("box", self.prog_box), ("box_open", self.prog_box),
                                                                 ("ground", self.prog_box), ("cyl", self.prog_prism))}
        self._points = moderngl.POINTS
        self._meshes: dict[str, list] = {}
        self._mesh_names: list[str] = []
        #: the terrain's patch, culled per frame: name -> (vertices (V, 3) float64, faces (F, 3) int32, index
        #: buffer, world_from_mesh (4, 4) of this frame)
        self._culled: dict[str, list] = {}
        self._planes = pattern_planes(layout.direction_image()) if cull_terrain else None
        self._origin = np.zeros(3)
        self._depth_test = moderngl.DEPTH_TEST

    # -- set-up ------------------------------------------------------------------------------------------------
    def _solids(self, prog, reserve: int = 64) -> list:
        """[vao, instance buffer, count] of convex solids drawn as one point per instance record."""
        inst = self._m(self.ctx.buffer(reserve=reserve * INSTANCE_FLOATS * 4, dynamic=True))
        fmt = (inst, "16f 3f", "in_model", "in_colour") if "in_colour" in prog else (inst, "16f 12x", "in_model")
        return [self._m(self.ctx.vertex_array(prog, [fmt])), inst, 0]

    def _instanced(self, vertices: np.ndarray, faces: np.ndarray, reserve: int = 64) -> list:
        """[vao, instance buffer, count] of a unit mesh drawn per instance record."""
        ctx = self.ctx
        vbo = self._m(ctx.buffer(np.asarray(vertices, np.float32).tobytes()))
        ibo = self._m(ctx.buffer(np.asarray(faces, np.int32).tobytes()))
        inst = self._m(ctx.buffer(reserve=reserve * INSTANCE_FLOATS * 4, dynamic=True))
        fmt = (inst, "16f 3f/i", "in_model", "in_colour") if "in_colour" in self.prog_inst else \
            (inst, "16f 12x/i", "in_model")
        vao = self._m(ctx.vertex_array(self.prog_inst, [(vbo, "3f", "in_pos"), fmt], index_buffer=ibo,
                                       index_element_size=4))
        return [vao, inst, 0, ibo]

    def _buffers(self) -> _Buffers:
        """A framebuffer of the target's attachments (encoded RGBA8UI, depth, optional shaded RGBA8)."""
        ctx, size = self.ctx, (self.layout.shape[1], self.layout.shape[0])
        enc, depth = self._m(ctx.renderbuffer(size, 4, dtype="u1")), self._m(ctx.depth_renderbuffer(size))
        atts, clears = [enc], [(self._m(ctx.framebuffer([enc], depth)), (0.0, 0.0, 0.0, 0.0))]
        if self.rgb:
            atts.append(self._m(ctx.renderbuffer(size, 4, dtype="f1")))
            clears.append((self._m(ctx.framebuffer([atts[-1]])), SKY_RGBA))
        return _Buffers(self._m(ctx.framebuffer(atts, depth)), clears)

    def set_scene(self, scene: Scene) -> None:
        """Upload one frame: box (the ground slab among them) and cylinder instances, mesh poses, grain heights."""
        self.make_current()
        self._origin = scene.heightfield.world_from_grid[:3, 3].copy()
        boxes = box_instances(scene.boxes, self._origin)
        ground = np.zeros(len(boxes), bool)
        self._ground = None
        if scene.ground_box is not None:
            ground[scene.ground_box] = True
            self._ground = (scene.boxes.world_from_box[scene.ground_box], scene.boxes.half_extents[scene.ground_box])
        hidden = np.zeros(len(boxes), bool) if scene.boxes.hidden_top is None else scene.boxes.hidden_top
        upload_instances(self._units["box"], boxes[~ground & ~hidden])
        upload_instances(self._units["box_open"], boxes[~ground & hidden])    # top covered: bounded by its sides
        upload_instances(self._units["ground"], boxes[ground])
        upload_instances(self._units["cyl"], cylinder_instances(scene.cylinders, self._origin))
        self._surface.upload(scene, self._origin)
        for mesh in scene.meshes:
            if mesh.name not in self._meshes:
                self._meshes[mesh.name] = self._instanced(mesh.vertices, mesh.faces, reserve=1)
            if self._planes is not None and mesh.name.startswith(TERRAIN_MESH_PREFIX):
                if mesh.name not in self._culled:                     # the patch moved on: keep the new one's
                    self._culled = {mesh.name: [np.asarray(mesh.vertices, np.float64),
                                                np.asarray(mesh.faces, np.int32), self._meshes[mesh.name][3], None]}
                self._culled[mesh.name][3] = np.asarray(mesh.world_from_mesh, np.float64)
            upload_instances(self._meshes[mesh.name],
                         pack_instances(mesh.world_from_mesh[None], np.array([mesh.colour]), self._origin))
        self._mesh_names = [m.name for m in scene.meshes]

    # -- per frame ---------------------------------------------------------------------------------------------
    def draw(self, k: int, world_from_sensor: np.ndarray) -> None:
        """Draw every beam of the LiDAR at ``world_from_sensor`` (4 x 4, sensor axes X right, Y up, Z forward)."""
        check_target(k)
        local = np.eye(4)
        local[:3, 3] = self._origin
        sensor_from_local = np.linalg.inv(world_from_sensor) @ local                  # float64, then float32
        light = tuple(np.asarray(world_from_sensor)[:3, :3].T @ SUN_WORLD)
        front = 1.0 if np.linalg.det(sensor_from_local[:3, :3]) > 0.0 else -1.0
        for prog in self._progs:
            prog["u_sensor_from_local"].write(_mat(sensor_from_local))
            for name, value in (("u_front", front), ("u_cull", True), ("u_light", light)):
                set_uniform(prog, name, value)
        self.ctx.enable(self._depth_test)
        self.ctx.disable(self.ctx.CULL_FACE)
        self._row_tex.use(0)
        self._dir_tex.use(1)
        key = None if self._ground is None else ground_key(*self._ground, world_from_sensor, self.far_m)
        begin_frame(self.ctx, self._frame, self._ground_img, key, self._buffers, lambda: self._render("ground"))
        self._render("cyl")
        self._surface.render()
        self._render("box")
        self._render("box_open")
        if key is None:
            self._render("ground")
        set_uniform(self.prog_inst, "u_cull", False)                  # mesh files have unknown winding: two-sided
        for name in self._mesh_names:
            if name in self._culled:
                self._render_culled(name, world_from_sensor)
            else:
                self._meshes[name][0].render(instances=1)

    def _render_culled(self, name: str, world_from_sensor: np.ndarray) -> None:
        """Draw the triangles of mesh ``name`` that a beam may meet (renderer_proc/gl/meshcull.py), in order."""
        vertices, faces, ibo, world_from_mesh = self._culled[name]
        sensor_from_mesh = np.linalg.inv(world_from_sensor) @ world_from_mesh
        points = vertices @ sensor_from_mesh[:3, :3].T + sensor_from_mesh[:3, 3]
        kept = visible_faces(points, faces, *self._planes)
        if kept.size:
            ibo.write(np.ascontiguousarray(kept).tobytes())
            self._meshes[name][0].render(vertices=kept.size, instances=1)

    def _render(self, name: str) -> None:
        vao, _, n = self._units[name]
        if n:
            set_uniform(self.prog_box, "u_open_top", name == "box_open")
            vao.render(mode=self._points, vertices=n)

    def _check(self, out: np.ndarray) -> None:
        want = self.layout.shape + (4,)
        if out.shape != want or out.dtype != np.uint8 or not out.flags.c_contiguous:
            raise ValueError(f"destination must be C-contiguous {want} uint8, got {out.shape} {out.dtype}")

    def read_depth(self, k: int, out: np.ndarray) -> None:
        """The encoded ranges into ``out`` (rows, cols, 4) uint8 in place (row r = elevation row r)."""
        check_target(k)
        self._check(out)
        self._frame.draw.read_into(out, components=4, attachment=0, alignment=1, dtype="u1")

    def read_rgb(self, k: int, out: np.ndarray) -> None:
        """The shaded beams into ``out`` (rows, cols, 4) uint8 in place."""
        check_target(k)
        if not self.rgb:
            raise ValueError("this renderer was made without the rgb output")
        self._check(out)
        self._frame.draw.read_into(out, components=4, attachment=1, alignment=1, dtype="f1")
