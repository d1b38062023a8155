"""The grain surface's GL objects, shared by both GL renderers: upload each frame and draw.

The surface is :class:`~renderer_proc.gl.hfmesh.SurfaceMesh`'s: the height field's grid with its flat blocks merged,
exactly the piecewise-linear surface of :func:`cosim.world.heightfield.surface_height` (same diagonal). Vertex
heights are written when the grain heights change, the index list only when the flat blocks change, the model
matrix relative to the renderer's origin every frame.

Two index lists: :meth:`SurfaceMesh.triangles` (the camera renderer, and the beam-native triangle path
``beam.geom`` -> ``beam.frag``), or :meth:`SurfaceMesh.quads` (``quads=True``, the beam-native default: four
vertices a ``lines_adjacency`` primitive through ``beam_quad.geom`` -> ``beam_quad.frag``, a quad's two triangles
bounded once and tested in one fragment per beam; drawn as triangles each grid quad's bounding rectangle is
rasterised and shaded twice). The triangle path of the beam-native renderer is kept for side-by-side
measurement (``python bench/run.py beam_surface``) and as the tests' second reference.
"""
from __future__ import annotations

from typing import Any, Callable

import numpy as np

from cosim.world.heightfield import padded_heights
from cosim.world.scene import Scene
from renderer_proc.gl.hfmesh import SurfaceMesh

__all__ = ["Surface", "mat_bytes"]


def mat_bytes(m: np.ndarray) -> bytes:
    """A numpy 4 x 4 as GLSL column-major float32 bytes (a ``mat4`` uniform's)."""
    return np.asarray(m, dtype=np.float32).T.tobytes()


class Surface:
    """The grain surface for program ``prog`` (attributes ``in_xy``, ``in_h``; uniform ``u_model``), its GL
    objects made in ``ctx`` through ``make`` (the renderer's :meth:`~renderer_proc.gl.backend.GLResources._m`);
    ``quads``: draw :meth:`SurfaceMesh.quads` as ``lines_adjacency`` primitives instead of triangles."""

    def __init__(self, ctx: Any, make: Callable[[Any], Any], prog: Any, *, quads: bool = False):
        import moderngl  # the context exists: the renderer has imported it already

        self.ctx, self._make, self._prog, self.quads = ctx, make, prog, quads
        self._mode = moderngl.LINES_ADJACENCY if quads else moderngl.TRIANGLES
        self.mesh: SurfaceMesh | None = None
        self._heights = self._vao = self._indices = None
        self._uploaded: bytes | None = None       # the grain heights' bytes on the GPU (None: none yet)
        self.count = 0                           # indices drawn per frame

    def _build(self, hf) -> None:
        nx, ny = hf.heights.shape
        ctx, m = self.ctx, self._make
        self.mesh = SurfaceMesh(nx, ny, hf.cell_m, hf.length_m, hf.width_m)
        xy = m(ctx.buffer(self.mesh.vertices.tobytes()))
        self._heights = m(ctx.buffer(reserve=len(self.mesh.vertices) * 4, dynamic=True))
        self._indices = m(ctx.buffer(reserve=2 * (nx + 1) * (ny + 1) * 3 * 4, dynamic=True))
        self._vao = m(ctx.vertex_array(self._prog, [(xy, "2f", "in_xy"), (self._heights, "1f", "in_h")],
                                       index_buffer=self._indices, index_element_size=4))

    @property
    def primitives(self) -> int:
        """Quads (or triangles) drawn per frame."""
        return self.count // (4 if self.quads else 3)

    def upload(self, scene: Scene, origin: np.ndarray) -> None:
        """Vertex heights and the index list when the grain heights' bytes change (a quarter of the default run's
        frames keep them: the auger off), the index list only when the flat blocks change too, the model matrix
        relative to ``origin`` (3,) m (the renderer's world-frame origin) every frame."""
        hf = scene.heightfield
        heights = np.asarray(hf.heights, dtype=np.float32)
        if self.mesh is None or self.mesh.shape != heights.shape:
            self._build(hf)
            self._uploaded = None
        raw = heights.tobytes()                  # bytes, not values: -0.0 and 0.0 stay apart
        if raw != self._uploaded:
            self._upload_heights(padded_heights(heights))
            self._uploaded = raw
        local = hf.world_from_grid.copy()
        local[:3, 3] -= origin
        self._prog["u_model"].write(mat_bytes(local))

    def _upload_heights(self, hp: np.ndarray) -> None:
        """Write the vertex heights of ``hp`` (nx + 2, ny + 2) float32 m (:func:`padded_heights`), and the index
        list where its flat blocks changed."""
        self._heights.write(self.mesh.heights(hp))
        idx, changed = self.mesh.quads(hp) if self.quads else self.mesh.triangles(hp)
        if changed:
            if idx.nbytes > self._indices.size:
                self._indices.orphan(idx.nbytes)
            self._indices.write(idx)
            self.count = idx.size

    def render(self) -> None:
        """Draw the surface (into the framebuffer in use)."""
        if self.count:
            self._vao.render(mode=self._mode, vertices=self.count)
