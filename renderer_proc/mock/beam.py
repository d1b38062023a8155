"""The beam-native mock renderer: the exact ray cast of the beams only, encoded with the paper's codec.

With ``sensor.method: beam_native`` and ``renderer: mock`` this is the whole renderer: each frame it casts
the N beam directions from the LiDAR origin through the :class:`~cosim.world.scene.Scene`
(``cosim.world.fastcast``: Embree when installed, else the numpy ``cosim.world.raycast``; exact for every
primitive) and writes the range along each beam with Eqs 1-2
(``renderer_proc.codec.encode_depth``) into the beams target (``cosim.world.beamtarget``). The GL
beam-native renderer writes the same bytes to the codec's rounding; this is its oracle and the fast path
without a GPU (one cast per beam instead of one per camera pixel).

The optional shaded image is grey Lambert shading from normals estimated on neighbouring beams' points
(gridded patterns; a CSV table, with no neighbours, is flat grey).
"""
from __future__ import annotations

import numpy as np

from cosim.scenario.config.sensing import Codec
from cosim.world.beamtarget import BeamLayout
from cosim.world.fastcast import Backend, cast_from, make_caster
from cosim.world.scene import SKY_RGBA, SUN_WORLD, Scene
from renderer_proc.codec import encode_depth
from renderer_proc.mock.backend import AMBIENT, DIFFUSE, MOCK_GREY

__all__ = ["MockBeamRenderer", "beam_ranges", "check_target"]


def check_target(k: int) -> None:
    """A beam-native renderer has one target, number 0; anything else is a caller's error."""
    if k != 0:
        raise IndexError(f"a beam-native renderer has one target (0), asked for {k}")



def beam_ranges(scene: Scene, world_from_sensor: np.ndarray, directions: np.ndarray,
                backend: Backend = "auto") -> np.ndarray:
    """Exact range along each beam: ``directions`` (N, 3) unit, sensor frame; ``world_from_sensor`` 4 x 4.
    Returns (N,) float64 m, inf where the beam hits nothing: Embree when installed, else the numpy ray cast
    (``cosim.world.fastcast``, ``backend``; the two agree to well under the codec's rounding)."""
    d_world = np.asarray(directions, np.float64) @ world_from_sensor[:3, :3].T
    return cast_from(scene, world_from_sensor[:3, 3], d_world, backend)


class MockBeamRenderer:
    """The beam-native renderer interface (as :class:`renderer_proc.gl.beam.GLBeamRenderer`): ``set_scene``,
    ``draw(0, world_from_sensor)``, ``read_depth(0, out)``, ``read_rgb(0, out)``, ``close``: the camera
    renderers' interface with a single target, number 0. ``backend``: the ray cast's (``cosim.world.fastcast``;
    ``auto``: Embree when installed). ``parts`` (``cosim.world.parts.entity_parts(scenario)``): the scenes'
    rigid bodies, built once for the run when Embree allows (``caster.name`` says which ray caster runs)."""

    def __init__(self, layout: BeamLayout, codec: Codec, *, rgb: bool = False, backend: Backend = "auto",
                 parts=None):
        self.layout, self.codec, self.rgb, self.backend = layout, codec, rgb, backend
        self.caster = make_caster(parts, backend)
        self._scene: Scene | None = None
        self._range: np.ndarray | None = None
        self._pose: np.ndarray | None = None

    def set_scene(self, scene: Scene) -> None:
        """Use ``scene`` for the following draws."""
        self._scene = scene

    def draw(self, k: int, world_from_sensor: np.ndarray) -> None:
        """Cast every beam from the LiDAR at ``world_from_sensor`` (4 x 4, sensor axes X right, Y up, Z forward)."""
        if self._scene is None:
            raise RuntimeError("set_scene must be called before draw")
        check_target(k)
        d_world = self.layout.directions @ np.asarray(world_from_sensor, np.float64)[:3, :3].T
        self._range = self.caster.cast(self._scene, world_from_sensor[:3, 3], d_world)
        self._pose = np.array(world_from_sensor, np.float64)

    def ranges(self) -> np.ndarray:
        """The last draw's exact ranges (N,) float64 m, inf on a miss."""
        if self._range is None:
            raise RuntimeError("draw must be called before reading")
        return self._range

    def read_depth(self, k: int, out: np.ndarray) -> None:
        """Encoded ranges (Eqs 1-2) into ``out`` (rows, cols, 4) uint8 in place; padding pixels invalid."""
        check_target(k)
        r = self.ranges()
        lay = self.layout
        if out.shape != lay.shape + (4,) or out.dtype != np.uint8:
            raise ValueError(f"destination must be {lay.shape + (4,)} uint8, got {out.shape} {out.dtype}")
        full = r
        if lay.pixels != lay.n_beams:                   # padding pixels: no hit
            full = np.full(lay.pixels, np.inf)
            full[:lay.n_beams] = r
        encode_depth(full.reshape(lay.shape), self.codec, out=out)

    def read_rgb(self, k: int, out: np.ndarray) -> None:
        """Grey-shaded image of the beams into ``out`` (rows, cols, 4) uint8 in place (sky where no hit)."""
        check_target(k)
        r, lay = self.ranges(), self.layout
        hit = np.zeros(lay.pixels, bool)
        hit[:lay.n_beams] = np.isfinite(r)
        shade = np.full(lay.pixels, MOCK_GREY * AMBIENT)
        if lay.gridded and min(lay.shape) > 1:
            p = (lay.directions * np.where(np.isfinite(r), r, 0.0)[:, None]).reshape(lay.shape + (3,))
            n = np.cross(np.gradient(p, axis=1), np.gradient(p, axis=0))
            n /= np.maximum(np.linalg.norm(n, axis=2, keepdims=True), 1e-12)
            sun = SUN_WORLD @ self._pose[:3, :3]                                 # sensor frame
            shade = (MOCK_GREY * (AMBIENT + DIFFUSE * np.abs(n @ sun))).ravel()
        rgb = np.where(hit[:, None], shade[:, None], np.array(SKY_RGBA[:3]))
        out[..., :3] = np.clip(np.floor(rgb * 255.0 + 0.5), 0, 255).astype(np.uint8).reshape(lay.shape + (3,))
        out[..., 3] = 255

    def close(self) -> None:
        """Release the ray caster's scenes."""
        self._scene = None
        self.caster.close()
