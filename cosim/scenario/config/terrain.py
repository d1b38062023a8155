"""The field surface under the machines (``terrain:``; cosim.world.terrain, docs/field.md). Owned by
dynamics_proc; the renderer draws it."""
from __future__ import annotations

from pathlib import Path

from pydantic import Field, model_validator

from .base import Model, NonNegFloat, PosFloat
from .limits import key_error

__all__ = ["Terrain", "MAX_SLOPE_PCT", "MAX_TERRAIN_CELLS", "MAX_RENDER_CELLS_PER_SIDE"]

#: grades and cross slopes beyond this (percent) are not a harvested field (and leave the small-angle models)
MAX_SLOPE_PCT = 30.0
#: most samples of a terrain grid (the roughness tile ``(tile_m / cell_m)^2``, a height map's nx ny, or the
#: square a height map's roughness is drawn on): 2048 x 2048. Drawing the roughness takes about 40 B a cell at its
#: peak (noise, kernel and their FFTs), so about 170 MB and 0.4 s on a 2-core laptop, in validate and in each of
#: the three processes that build the ground (measured with tracemalloc on cosim.world.terrain.rough_field)
MAX_TERRAIN_CELLS = 1 << 22
#: most cells along a side of the patch the renderer draws (``render_extent_m / cell_m``): 1024 x 1024 cells are
#: two million triangles, rebuilt each time the patch moves
MAX_RENDER_CELLS_PER_SIDE = 1024


class Terrain(Model):
    """The ground: a plane (``grade_pct`` along world x, ``cross_slope_pct`` along world y, rise per run in per
    cent) plus seeded random roughness and/or a height-map file. Every value 0 and no file: flat ground (the
    default; the results are those of a flat world to the bit).

    * ``roughness_rms_m``, ``correlation_length_m``: a stationary Gaussian random field of this standard deviation
      and Gaussian autocorrelation ``rms^2 exp(-r^2 / L^2)`` (its spectrum ``rms^2 pi L^2 exp(-k^2 L^2 / 4)``),
      drawn from the scenario's seed on a periodic tile of ``tile_m`` sampled every ``cell_m``;
    * ``height_map_file``: a ``.npy`` array (nx, ny) of heights, m, sampled every ``cell_m`` along world x and y
      from ``origin_xy_m`` (relative to the scenario file); outside it the edge value holds;
    * ``render_extent_m``: side of the square patch of the surface the renderer draws around the cart (beyond it
      the LiDAR sees no ground).
    """

    grade_pct: float = Field(default=0.0, ge=-MAX_SLOPE_PCT, le=MAX_SLOPE_PCT, allow_inf_nan=False)
    """Slope of the ground plane along world x, rise per run in per cent."""
    cross_slope_pct: float = Field(default=0.0, ge=-MAX_SLOPE_PCT, le=MAX_SLOPE_PCT, allow_inf_nan=False)
    """Slope of the ground plane along world y, rise per run in per cent."""
    roughness_rms_m: NonNegFloat = Field(default=0.0, le=0.5)
    """Standard deviation of the seeded random roughness (a Gaussian random field), m (0: none)."""
    correlation_length_m: PosFloat = 2.0
    """Correlation length L of the roughness (autocorrelation rms^2 exp(-r^2 / L^2)), m."""
    cell_m: float = Field(default=0.5, ge=0.05, le=2.0, allow_inf_nan=False)
    """Sampling step of the roughness tile and of height_map_file, m."""
    tile_m: float = Field(default=128.0, ge=16.0, le=1024.0, allow_inf_nan=False)
    """Side of the periodic tile the roughness is drawn on, m."""
    height_map_file: Path | None = None
    """A .npy array (nx, ny) of heights, m, sampled every cell_m from origin_xy_m; relative to the scenario file."""
    origin_xy_m: tuple[float, float] = (0.0, 0.0)
    """World position of the height map's first sample, m."""
    render_extent_m: float = Field(default=40.0, ge=10.0, le=400.0, allow_inf_nan=False)
    """Side of the square patch of the surface the renderer draws around the cart, m."""

    @model_validator(mode="after")
    def _bounded(self) -> "Terrain":
        """The grids this ground needs fit (:data:`MAX_TERRAIN_CELLS`, :data:`MAX_RENDER_CELLS_PER_SIDE`),
        checked from the numbers alone, before any is allocated."""
        side = self.tile_m / self.cell_m
        if self.roughness_rms_m > 0.0 and self.height_map_file is None and side * side > MAX_TERRAIN_CELLS:
            smallest = self.tile_m / MAX_TERRAIN_CELLS ** 0.5
            raise key_error("Terrain", ("tile_m",), f"a {self.tile_m:g} m tile of {self.cell_m:g} m cells is "
                            f"{side:,.0f} x {side:,.0f} samples of roughness; at most {MAX_TERRAIN_CELLS:,} (2048 x "
                            f"2048) fit: use a smaller tile_m or a cell_m of at least {smallest:.3g} m", self.tile_m)
        patch = self.render_extent_m / self.cell_m
        if not self.flat and patch > MAX_RENDER_CELLS_PER_SIDE:
            raise key_error("Terrain", ("render_extent_m",), f"a {self.render_extent_m:g} m patch of {self.cell_m:g} "
                            f"m cells is {patch:,.0f} cells a side for the renderer; at most "
                            f"{MAX_RENDER_CELLS_PER_SIDE} fit: use a smaller render_extent_m or a larger cell_m",
                            self.render_extent_m)
        return self

    @model_validator(mode="after")
    def _resolvable(self) -> "Terrain":
        if self.roughness_rms_m > 0.0 and self.correlation_length_m < 2.0 * self.cell_m:
            raise ValueError(f"correlation_length_m ({self.correlation_length_m:g}) must be at least twice cell_m "
                             f"({self.cell_m:g}): the roughness would not be resolved")
        if self.roughness_rms_m > 0.0 and self.correlation_length_m > self.tile_m / 8.0:
            raise ValueError(f"correlation_length_m ({self.correlation_length_m:g}) must be at most tile_m / 8 "
                             f"({self.tile_m / 8.0:g}): the periodic tile would correlate with itself")
        return self

    @property
    def flat(self) -> bool:
        """Whether this is flat ground (no slope, no roughness, no file)."""
        return (self.grade_pct == 0.0 and self.cross_slope_pct == 0.0 and self.roughness_rms_m == 0.0
                and self.height_map_file is None)
