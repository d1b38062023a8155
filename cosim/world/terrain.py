"""The field surface: a plane, seeded Gaussian roughness and/or a height map (``terrain:``; docs/field.md).

``z(x, y) = grade x + cross y + r(x, y) + f(x, y)`` in world metres (x forward along the combine's initial
heading, y left, z up), with

* the plane: ``grade`` = ``grade_pct / 100`` (dz/dx), ``cross`` = ``cross_slope_pct / 100`` (dz/dy);
* ``r``: a stationary Gaussian random field of standard deviation ``roughness_rms_m`` and Gaussian
  autocorrelation ``C(d) = rms^2 exp(-d^2 / L^2)``, L = ``correlation_length_m`` (:func:`rough_field`: white noise
  convolved with the kernel ``exp(-2 d^2 / L^2)`` on a periodic tile, whose self-convolution is that correlation,
  scaled to the exact variance), drawn from the scenario's seed, periodic over ``tile_m``;
* ``f``: a height map from a ``.npy`` file, clamped beyond its edges.

Between samples (``cell_m`` apart) the surface is linear on two triangles per cell (split along the diagonal
from sample (i, j) to (i + 1, j + 1)); :meth:`Terrain.mesh` gives the same triangles to the renderer, so the
wheels stand on the surface that is drawn.
Flat ground is :data:`None` throughout: :func:`terrain_of` returns None and every caller keeps the flat code path.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np

from cosim.scenario.config import Scenario

from .height_map import read_height_map

__all__ = ["TERRAIN_STREAM", "PCT", "Terrain", "rough_field", "terrain_of"]

#: the roughness's random stream: numpy's SeedSequence(seed, spawn_key=(TERRAIN_STREAM,)), apart from the others
TERRAIN_STREAM = 1
#: per cent
PCT = 100.0


def rough_field(rms_m: float, corr_m: float, n: int, cell_m: float, seed: int) -> np.ndarray:
    """A periodic (n, n) float64 Gaussian random field of standard deviation ``rms_m`` (m, the expectation of
    its variance exactly) and autocorrelation ``rms^2 exp(-d^2 / corr^2)``, sampled every ``cell_m`` (m).

    Unit white noise convolved (circularly, by FFT) with the kernel ``k(d) = exp(-2 d^2 / corr^2)``, whose
    self-convolution is proportional to ``exp(-d^2 / corr^2)``, divided by ``sqrt(sum k^2)`` (the standard
    deviation of that convolution) and times ``rms_m``. Valid while ``corr`` is well below the tile and above
    the cell."""
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(TERRAIN_STREAM,)))
    noise = rng.standard_normal((n, n))
    d = np.minimum(np.arange(n), n - np.arange(n)) * cell_m         # periodic distance to sample 0
    kernel = np.exp(-2.0 * (d[:, None] ** 2 + d[None, :] ** 2) / corr_m ** 2)
    field = np.fft.irfft2(np.fft.rfft2(noise) * np.fft.rfft2(kernel), s=(n, n))
    return field * (rms_m / float(np.sqrt(np.sum(kernel ** 2))))


@dataclass(frozen=True)
class Terrain:
    """Height of the field. ``samples`` (nx, ny) float64 m at (origin + (i, j) cell) (None: the plane alone);
    ``periodic``: the samples repeat (roughness tile) rather than clamp (a height-map file)."""

    grade: float
    cross: float
    samples: np.ndarray | None
    cell_m: float
    origin_xy: tuple[float, float]
    periodic: bool
    render_extent_m: float
    #: the last patch made (name -> (name, vertices, faces, translation), read-only): a patch is the same
    #: while the cart stays within its quarter step, so it is made once per step, not per frame
    _patch: dict = field(default_factory=dict, compare=False, repr=False)

    def _indices(self, x: np.ndarray, y: np.ndarray):
        """Cell (i, j) (int64) and the fractions (fx, fy) in [0, 1] of points (x, y) m."""
        gx = (x - self.origin_xy[0]) / self.cell_m
        gy = (y - self.origin_xy[1]) / self.cell_m
        nx, ny = self.samples.shape
        if not self.periodic:
            gx, gy = np.clip(gx, 0.0, nx - 1.0), np.clip(gy, 0.0, ny - 1.0)
        i, j = np.floor(gx), np.floor(gy)
        return i.astype(np.int64), j.astype(np.int64), gx - i, gy - j

    def _sample(self, i: np.ndarray, j: np.ndarray) -> np.ndarray:
        nx, ny = self.samples.shape
        if self.periodic:
            return self.samples[i % nx, j % ny]
        return self.samples[np.clip(i, 0, nx - 1), np.clip(j, 0, ny - 1)]

    def height(self, x, y) -> np.ndarray:
        """Ground height z (m) under world points ``x``, ``y`` (any matching shapes, m): the plane plus the
        samples' piecewise-linear interpolation on the cells' two triangles."""
        x, y = np.asarray(x, np.float64), np.asarray(y, np.float64)
        z = self.grade * x + self.cross * y
        if self.samples is None:
            return z
        i, j, fx, fy = self._indices(x, y)
        z00, z11 = self._sample(i, j), self._sample(i + 1, j + 1)
        lower = fx >= fy                      # the cell's triangle (i, j), (i + 1, j), (i + 1, j + 1), else the other
        z10, z01 = self._sample(i + 1, j), self._sample(i, j + 1)
        r = np.where(lower, z00 + fx * (z10 - z00) + fy * (z11 - z10), z00 + fy * (z01 - z00) + fx * (z11 - z01))
        return z + r

    def mesh(self, centre_xy: tuple[float, float]) -> tuple[str, np.ndarray, np.ndarray, np.ndarray]:
        """The patch the renderer draws: (name, vertices (V, 3) float64 m relative to its origin, faces (F, 3)
        int64, world_from_patch translation (3,) m). The patch is a square of about ``render_extent_m`` on the
        sample lattice, re-centred in steps of a quarter of it (its name changes with it, so that a renderer
        can keep the triangles while it stays); two triangles per cell, so the drawn surface is the samples
        joined by planar triangles."""
        if self.samples is None:                     # the plane alone: two triangles are exact
            return self._plane_mesh(centre_xy)
        step = self.cell_m
        n = max(2, int(round(self.render_extent_m / step)))
        snap = max(1, n // 4)
        ci = int(np.floor((centre_xy[0] - self.origin_xy[0]) / step / snap)) * snap - n // 2
        cj = int(np.floor((centre_xy[1] - self.origin_xy[1]) / step / snap)) * snap - n // 2
        name = f"terrain@{ci},{cj}"
        if name not in self._patch:
            self._patch.clear()
            self._patch[name] = self._lattice_patch(name, ci, cj, n)
        return self._patch[name]

    def _lattice_patch(self, name: str, ci: int, cj: int, n: int) -> tuple[str, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`mesh` of the samples: the patch of ``n`` cells a side from sample (``ci``, ``cj``), its
        arrays read-only (shared by every frame that draws it)."""
        step = self.cell_m
        x0, y0 = self.origin_xy[0] + ci * step, self.origin_xy[1] + cj * step
        u = np.arange(n + 1) * step
        xs, ys = np.meshgrid(x0 + u, y0 + u, indexing="ij")
        z = self.height(xs, ys)
        verts = np.stack([xs - x0, ys - y0, z], axis=-1).reshape(-1, 3)
        k = np.arange(n)
        a = (k[:, None] * (n + 1) + k[None, :]).ravel()                  # vertex (i, j)
        faces = np.concatenate([np.stack([a, a + n + 1, a + n + 2], 1), np.stack([a, a + n + 2, a + 1], 1)])
        out = (verts, faces.astype(np.int64), np.array([x0, y0, 0.0]))
        for arr in out:
            arr.flags.writeable = False
        return (name, *out)


    def _plane_mesh(self, centre_xy: tuple[float, float]) -> tuple[str, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`mesh` of the plane: one square of ``render_extent_m`` as two triangles, re-centred in steps of
        a quarter of it."""
        snap = self.render_extent_m / 4.0
        x0 = float(np.floor(centre_xy[0] / snap)) * snap - 2.0 * snap
        y0 = float(np.floor(centre_xy[1] / snap)) * snap - 2.0 * snap
        u = np.array([0.0, 4.0 * snap])
        xs, ys = np.meshgrid(x0 + u, y0 + u, indexing="ij")
        verts = np.stack([xs - x0, ys - y0, self.height(xs, ys)], axis=-1).reshape(-1, 3)
        faces = np.array([[0, 2, 3], [0, 3, 1]], dtype=np.int64)
        return f"terrain@{x0:g},{y0:g}", verts, faces, np.array([x0, y0, 0.0])


@functools.lru_cache(maxsize=8)
def _terrain(grade: float, cross: float, rms: float, corr: float, cell: float, tile: float, seed: int,
             path: str | None, origin: tuple[float, float], extent: float) -> Terrain:
    if path is not None:
        samples = read_height_map(path)
        if rms > 0.0:
            n = samples.shape
            grid = rough_field(rms, corr, max(n), cell, seed)[: n[0], : n[1]]
            samples = samples + grid
        return Terrain(grade, cross, samples, cell, origin, False, extent)
    if rms > 0.0:
        n = int(round(tile / cell))
        return Terrain(grade, cross, rough_field(rms, corr, n, cell, seed), cell, origin, True, extent)
    return Terrain(grade, cross, None, cell, origin, False, extent)


def terrain_of(s: Scenario) -> Terrain | None:
    """The scenario's terrain (built once per set of parameters), or None for flat ground."""
    t = s.terrain
    if t.flat:
        return None
    return _terrain(t.grade_pct / PCT, t.cross_slope_pct / PCT, t.roughness_rms_m, t.correlation_length_m, t.cell_m,
                    t.tile_m, s.seed, str(t.height_map_file) if t.height_map_file is not None else None,
                    tuple(t.origin_xy_m), t.render_extent_m)
