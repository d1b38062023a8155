"""Ranges of a beam-native frame: Eq 3 per beam, no back-projection, no resample (docs/lidar.md).

With ``sensor.method: beam_native`` the renderer writes one pixel per beam (``cosim.world.beamtarget``),
holding the depth-encoded range along that beam. Perception then reads the beams' words (one copy, the only
read of the shared image) and decodes each with the Eq 3 table (``perception_proc.lidar.codec.decode_lut``):
range = decoded value, to the codec's bound beta/510.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from cosim.scenario.config.sensing import Codec
from cosim.world.beamtarget import BeamLayout
from perception_proc.lidar.codec import decode_lut, decode_words
from perception_proc.lidar.resample import words_of

__all__ = ["BeamDecoder"]


class BeamDecoder:
    """Per-beam decoding of the beams target. ``gather(images)`` copies the beams' raw words out of the one
    target image (rows, cols, 4) uint8; ``decode(gathered, out)`` turns them into ranges (N,) float32 m,
    NaN where the beam has no valid return."""

    def __init__(self, layout: BeamLayout, codec: Codec):
        self.layout = layout
        self.lut = decode_lut(codec)

    def gather(self, images: Sequence[np.ndarray]) -> list[np.ndarray]:
        """The beams' RGBA words, a copy: [(N,) uint32]. ``images``: the single beams target."""
        if len(images) != 1:
            raise ValueError(f"a beam-native frame has one image (the beams target), got {len(images)}")
        img = images[0]
        if img.shape != self.layout.shape + (4,):
            raise ValueError(f"beams target has shape {img.shape}, the pattern needs {self.layout.shape + (4,)}")
        return [words_of(img).reshape(-1)[:self.layout.n_beams].copy()]

    def decode(self, gathered: list[np.ndarray], out: np.ndarray | None = None) -> np.ndarray:
        """Ranges (N,) float32 m from :meth:`gather`'s words, into ``out`` when given."""
        r = decode_words(gathered[0], self.lut)
        if out is None:
            return r
        out[:] = r
        return out

    def ranges(self, images: Sequence[np.ndarray], out: np.ndarray | None = None) -> np.ndarray:
        """:meth:`gather` then :meth:`decode`."""
        return self.decode(self.gather(images), out=out)
