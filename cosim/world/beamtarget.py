"""The beam-native LiDAR target: one pixel per beam (docs/lidar.md).

With ``sensor.method: beam_native`` the renderer draws from the LiDAR origin straight into a target whose
pixels are the beams, and perception decodes it per beam (Eq 3) with no back-projection or resample. This
module is the layout both sides share:

* grid and honeycomb patterns: the target is the range image itself, (elevation_count, azimuth_count) pixels,
  pixel (row, col) is beam ``row * cols + col`` (the pattern's row-major beam order,
  ``cosim.world.patterns``);
* CSV patterns: a direction table, beam i at flat pixel i of a (rows, :data:`TABLE_WIDTH`) target (the last
  row padded with pixels no beam reads, always invalid).

Each pixel holds the paper's depth-encoded RGBA8 (Eqs 1-2) of the *range along the beam* (not a planar
depth): the same codec, bound beta/510, decoded with the same table.
"""
from __future__ import annotations

import math

import numpy as np

from cosim.scenario.config import Pattern

from .camera import beam_directions
from .patterns import beam_table, pattern_shape

__all__ = ["BEAMS_CAMERA", "BEAMS_DEPTH_BLOCK", "BEAMS_RGB_BLOCK", "TABLE_WIDTH", "BeamLayout", "beam_layout"]

#: camera name of the beams target in the block names (``beams_depth``, ``beams_rgb``): the viewer's image
#: panels list every ``*_depth`` / ``*_rgb`` image, so the target shows there like a camera's
BEAMS_CAMERA = "beams"
BEAMS_DEPTH_BLOCK = f"{BEAMS_CAMERA}_depth"
BEAMS_RGB_BLOCK = f"{BEAMS_CAMERA}_rgb"
#: width of a CSV pattern's direction-table target, pixels
TABLE_WIDTH = 1024


class BeamLayout:
    """The beams of a pattern and where each lies in the target.

    ``elevation``, ``azimuth`` (N,) float64 rad and ``directions`` (N, 3) float64 unit vectors, sensor frame
    (X right, Y up, Z forward); ``shape`` (rows, cols) of the target; ``gridded``: True for grid / honeycomb
    (pixel = beam on the range image), False for a CSV direction table."""

    def __init__(self, pattern: Pattern):
        self.elevation, self.azimuth = beam_table(pattern)
        self.directions = beam_directions(self.elevation, self.azimuth)
        grid = pattern_shape(pattern)
        self.gridded = grid is not None
        n = self.n_beams
        if grid is not None:
            self.shape = (int(grid[0]), int(grid[1]))
        else:
            cols = min(n, TABLE_WIDTH)
            self.shape = (int(math.ceil(n / cols)), cols)

    @property
    def n_beams(self) -> int:
        return int(self.elevation.shape[0])

    @property
    def pixels(self) -> int:
        """Pixels of the target (>= beams; equal for gridded patterns)."""
        return self.shape[0] * self.shape[1]

    def beams_of(self, image: np.ndarray) -> np.ndarray:
        """The per-beam view of a target image: (rows, cols, ...) -> (N, ...) (no copy for gridded patterns)."""
        flat = image.reshape((self.pixels,) + image.shape[2:])
        return flat[:self.n_beams]

    def direction_image(self) -> np.ndarray:
        """(rows, cols, 3) float32 unit beam directions, sensor frame; zero on padding pixels."""
        d = np.zeros((self.pixels, 3), np.float32)
        d[:self.n_beams] = self.directions
        return d.reshape(self.shape + (3,))


def beam_layout(pattern: Pattern) -> BeamLayout:
    """The :class:`BeamLayout` of ``pattern`` (reads a CSV table from disk)."""
    return BeamLayout(pattern)
