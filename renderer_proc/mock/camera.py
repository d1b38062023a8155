"""The mock camera renderer: every camera view by exact ray cast, no OpenGL (docs/cameras.md).

Depth and labels are exact: each pixel centre's ray is cast through the :class:`~cosim.world.scene.Scene` by the
run's exact caster from ``cosim.world.fastcast.make_caster``. Where labels or colour are wanted, the scene's
triangles with their labels built in Embree every frame (the numpy label cast, ``cosim.world.labelcast``, without
Embree); else the rigid bodies built once in Embree when installed and ``parts`` are given, else the scene cast
per frame. Planar depth Z = t cos(angle to the optical axis), NaN where the ray meets nothing. The colour image is
plain: each label's flat colour (the scene's colours), lit by ``render.lighting`` (cosim.world.lighting) with
normals estimated from the depth image, no texture. A stereo matcher has nothing to match on it, so a stereo
camera is refused with the mock at validation (cosim.scenario.config.scenario).
"""
from __future__ import annotations

import numpy as np

from cosim.scenario.config.rendering import Lighting
from cosim.world.camera import Pinhole
from cosim.world.fastcast import make_caster
from cosim.world.labels import AUGER, CART_RIM, CART_WALL, COMBINE, GRAIN, GROUND, STREAM, TRACTOR
from cosim.world.lighting import irradiance, sun_direction
from cosim.world.parts import CART_COLOUR, COMBINE_COLOUR, TRACTOR_COLOUR
from cosim.world.scene import GRAIN_COLOUR, GROUND_COLOUR, SKY_RGBA, STREAM_COLOUR, Scene

__all__ = ["LABEL_COLOURS", "MockCameraRenderer", "normals_from_depth"]

#: flat linear-RGB colour of each label in the mock's colour image (the sky colour for label 0)
LABEL_COLOURS = np.array([SKY_RGBA[:3], GROUND_COLOUR, CART_COLOUR, CART_COLOUR, GRAIN_COLOUR, STREAM_COLOUR,
                          COMBINE_COLOUR, TRACTOR_COLOUR, COMBINE_COLOUR], dtype=np.float64)
assert [GROUND, CART_WALL, CART_RIM, GRAIN, STREAM, COMBINE, TRACTOR, AUGER] == list(range(1, 9))
_BYTE = 255.0


def normals_from_depth(pin: Pinhole, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Camera-frame points (H, W, 3) m of planar depth ``z`` (H, W) (0 where not finite) and unit normals
    (H, W, 3) from their image-space gradients (sign arbitrary: the shading is two-sided)."""
    uu, vv = pin.pixel_centres()
    p = pin.backproject(uu, vv, np.where(np.isfinite(z), z, 0.0))
    n = np.cross(np.gradient(p, axis=1), np.gradient(p, axis=0))
    n /= np.maximum(np.linalg.norm(n, axis=2, keepdims=True), 1e-12)
    return p, n


class MockCameraRenderer:
    """Same interface as ``renderer_proc.gl.camera.GLCameraRenderer``: ``set_scene``, ``draw``, ``read_rgb``,
    ``read_depth``, ``read_labels``. ``pins``: one pinhole per view; ``labelled``: per view, whether labels or
    colour are read from it (the label cast), else only depth (the fast cast); ``parts``
    (``cosim.world.parts.entity_parts(scenario)``): the scenes' rigid bodies, built once for the run for the fast
    cast when Embree allows (``caster.name`` says which ray caster runs)."""

    def __init__(self, pins: list[Pinhole], lighting: Lighting, labelled: list[bool], parts=None):
        self.pins, self.lighting, self.labelled = pins, lighting, labelled
        self.caster = make_caster(parts)
        self._sun = sun_direction(lighting)
        self._light: np.ndarray | None = None
        self._scene: Scene | None = None
        self._z: list[np.ndarray | None] = [None] * len(pins)
        self._labels: list[np.ndarray | None] = [None] * len(pins)
        self._pose: list[np.ndarray | None] = [None] * len(pins)

    def set_scene(self, scene: Scene, light: np.ndarray | None = None) -> None:
        """Use ``scene`` (and the work light at world ``light`` (3,), when there is one) for the next draws."""
        self._scene, self._light = scene, light

    def draw(self, k: int, world_from_camera: np.ndarray) -> None:
        """Ray-cast view ``k`` at ``world_from_camera`` (4, 4, camera axes)."""
        if self._scene is None:
            raise RuntimeError("set_scene must be called before draw")
        pin = self.pins[k]
        d_cam = pin.ray_directions()
        d = d_cam.reshape(-1, 3) @ world_from_camera[:3, :3].T
        origin = world_from_camera[:3, 3]
        if self.labelled[k]:
            t, lab = self.caster.cast_labels(self._scene, origin, d)
            self._labels[k] = lab.reshape(pin.height, pin.width)
        else:
            t = self.caster.cast(self._scene, origin, d)
        z = t.reshape(pin.height, pin.width) * d_cam[..., 2]
        self._z[k] = np.where(np.isfinite(z), z, np.nan)
        self._pose[k] = world_from_camera

    def _drawn(self, k: int) -> np.ndarray:
        z = self._z[k]
        if z is None:
            raise RuntimeError(f"view {k} has not been drawn")
        return z

    def read_depth(self, k: int, out: np.ndarray) -> None:
        """Planar depth of view k into ``out`` (H, W) float32 m, NaN where the ray meets nothing."""
        out[...] = self._drawn(k)

    def read_labels(self, k: int, out: np.ndarray) -> None:
        """Labels of view k into ``out`` (H, W) uint8 (cosim.world.labels; 0 where nothing is hit)."""
        self._drawn(k)
        if self._labels[k] is None:
            raise ValueError(f"view {k} was made without labels")
        out[...] = self._labels[k]

    def read_rgb(self, k: int, out: np.ndarray) -> None:
        """The plain colour image of view k into ``out`` (H, W, 4) uint8: each label's colour, lit (sky where
        nothing is hit). Linear values are stored as bytes, like the GL renderer's."""
        z = self._drawn(k)
        if self._labels[k] is None:
            raise ValueError(f"view {k} was made without colour")
        pose = self._pose[k]
        p, n = normals_from_depth(self.pins[k], z)
        world_n = n @ pose[:3, :3].T
        world_p = p @ pose[:3, :3].T + pose[:3, 3]
        light = irradiance(world_n, world_p, self.lighting, self._sun, self._light)
        rgb = LABEL_COLOURS[self._labels[k]] * np.minimum(light, 1.0)[..., None]
        rgb = np.where(np.isfinite(z)[..., None], rgb, LABEL_COLOURS[0])
        out[..., :3] = np.clip(np.floor(rgb * _BYTE + 0.5), 0, 255).astype(np.uint8)
        out[..., 3] = 255

    def close(self) -> None:
        """Release the ray caster's scenes."""
        self._scene = None
        self.caster.close()
