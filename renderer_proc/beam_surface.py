"""The grain surface in the GL beam-native renderer (:mod:`renderer_proc.beam_gl`): upload and draw.

The surface is :class:`~renderer_proc.hfmesh.SurfaceMesh`'s, drawn as its quads (:meth:`SurfaceMesh.quads`: a
fine block's grid quads, a plain merged block's rectangle, a fan's triangles in pairs) through the quad path
(``beam_heightfield.vert`` -> ``beam_quad.geom`` -> ``beam_quad.frag``, ``lines_adjacency`` input, four vertices
a primitive): a quad's two triangles share one bound in angle space and one fragment per beam in it, which tests
the beam against both exactly (nearest hit wins). The two triangles of a grid quad have the quad's bounding
rectangle, so drawn as triangles each quad's rectangle is rasterised and shaded twice; as a quad, once. The
surface is exactly the piecewise-linear one of :func:`cosim.world.heightfield.surface_height` (same diagonal).

``quads=False`` draws :meth:`SurfaceMesh.triangles` through the triangle path instead (``beam.geom`` ->
``beam.frag``, one triangle a primitive: the path before the quads, kept for side-by-side measurement,
``bench/beam_surface.py``, and as the tests' second reference).
"""
from __future__ import annotations

from typing import Any, Callable

import numpy as np

from cosim.world.heightfield import padded_heights
from cosim.world.scene import Scene

from .gl_backend import _mat
from .hfmesh import SurfaceMesh

__all__ = ["BeamSurface"]


class BeamSurface:
    """The grain surface's GL objects for the triangle program ``prog_tri`` and the quad program ``prog_quad``
    (both with ``in_xy``, ``in_h`` and ``u_model``), made in ``ctx`` through ``make`` (the renderer's
    :meth:`~renderer_proc.gl_backend.GLResources._m`)."""

    def __init__(self, ctx: Any, make: Callable[[Any], Any], prog_tri: Any, prog_quad: Any, *, quads: bool = True):
        self.ctx, self._make, self.quads = ctx, make, quads
        self._prog = prog_quad if quads else prog_tri
        self.mesh: SurfaceMesh | None = None
        self._heights = self._vao = self._indices = None
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
        """Vertex heights every frame, the index list when the flat blocks change, the model matrix relative to
        ``origin`` (3,) m (the renderer's world-frame origin)."""
        hf = scene.heightfield
        hp = padded_heights(np.asarray(hf.heights, dtype=np.float32))
        if self.mesh is None or self.mesh.shape != hf.heights.shape:
            self._build(hf)
        self._heights.write(self.mesh.heights(hp))
        idx, changed = self.mesh.quads(hp) if self.quads else self.mesh.triangles(hp)
        if changed:
            if idx.nbytes > self._indices.size:
                self._indices.orphan(idx.nbytes)
            self._indices.write(idx)
            self.count = idx.size
        local = hf.world_from_grid.copy()
        local[:3, 3] -= origin
        self._prog["u_model"].write(_mat(local))

    def render(self, lines_adjacency: int) -> None:
        """Draw the surface (``lines_adjacency``: moderngl's mode constant, for the quads)."""
        if self.count:
            self._vao.render(mode=lines_adjacency if self.quads else None, vertices=self.count)
