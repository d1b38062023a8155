"""The mock renderer: the same buffers as the GL renderer, from the exact ray cast (``cosim.world.fastcast``:
Embree when installed, else the numpy ray caster). No OpenGL.

For CI smoke runs and as an oracle. Each pixel centre's ray is cast through the :class:`Scene`; planar depth
is Z = t cos(angle to the optical axis); the bytes come from :func:`renderer_proc.codec.encode_depth`. Like
the GL renderer, hits nearer than the near plane or beyond the far plane count as no hit. The shaded image
is grey Lambert shading from normals estimated on the back-projected points (the ray caster returns
distances only).
"""
from __future__ import annotations

import numpy as np

from cosim.scenario.config.sensing import Codec
from cosim.world.camera import Rig
from cosim.world.fastcast import make_caster
from cosim.world.scene import SKY_RGBA, SUN_WORLD, Scene
from renderer_proc.codec import encode_depth, valid_depth_mask
from renderer_proc.projection import NEAR_M, far_plane_m, pixel_rays

__all__ = ["AMBIENT", "DIFFUSE", "MOCK_GREY", "MockRenderer"]

#: albedo of every surface in the mock's shaded image
MOCK_GREY = 0.7
#: ambient and diffuse shares of the shading (as in shaders/encode.frag)
AMBIENT, DIFFUSE = 0.35, 0.65


class MockRenderer:
    """Same interface as :class:`renderer_proc.gl.backend.GLRenderer`: ``set_scene``, ``draw``, ``read_*``.
    ``parts`` (``cosim.world.parts.entity_parts(scenario)``): the scenes' rigid bodies, built once for the run
    when Embree allows (``caster.name`` says which ray caster runs)."""

    def __init__(self, rig: Rig, codec: Codec, *, rgb: bool = False, float_depth: bool = False, parts=None):
        self.rig, self.codec, self.rgb, self.float_depth = rig, codec, rgb, float_depth
        self.caster = make_caster(parts)
        self._far = far_plane_m(codec.max_depth_m)
        self._scene: Scene | None = None
        self._z: list[np.ndarray | None] = [None] * len(rig)
        self._pose: list[np.ndarray | None] = [None] * len(rig)

    def set_scene(self, scene: Scene) -> None:
        """Use ``scene`` for the following draws."""
        self._scene = scene

    def draw(self, k: int, world_from_camera: np.ndarray) -> None:
        """Ray-cast camera ``k`` at ``world_from_camera``: planar depth (H, W) float64 m, inf for no hit."""
        if self._scene is None:
            raise RuntimeError("set_scene must be called before draw")
        cam = self.rig.cameras[k].intrinsics
        origin, dirs, cos = pixel_rays(cam, world_from_camera)
        t = self.caster.cast(self._scene, origin, dirs.reshape(-1, 3))
        z = t.reshape(cos.shape) * cos
        self._z[k] = np.where((z >= NEAR_M) & (z <= self._far), z, np.inf)
        self._pose[k] = world_from_camera

    def _depth(self, k: int) -> np.ndarray:
        z = self._z[k]
        if z is None:
            raise RuntimeError(f"camera {k} has not been drawn")
        return z

    def read_depth(self, k: int, out: np.ndarray) -> None:
        """Encoded bytes of camera k into ``out`` (H, W, 4) uint8, in place."""
        encode_depth(self._depth(k), self.codec, out=out)

    def read_zf(self, k: int, out: np.ndarray) -> None:
        """Planar depth of camera k into ``out`` (H, W) float32 m, NaN where invalid, in place."""
        z = self._depth(k)
        out[...] = np.where(valid_depth_mask(z, self.codec), z, np.nan)

    def read_rgb(self, k: int, out: np.ndarray) -> None:
        """Grey-shaded image of camera k into ``out`` (H, W, 4) uint8, in place (sky where no hit)."""
        z = self._depth(k)
        cam = self.rig.cameras[k].intrinsics
        uu, vv = cam.pixel_centres()
        p = cam.backproject(uu, vv, np.where(np.isfinite(z), z, 0.0))       # camera frame, m
        n = np.cross(np.gradient(p, axis=1), np.gradient(p, axis=0))
        n /= np.maximum(np.linalg.norm(n, axis=2, keepdims=True), 1e-12)
        sun = SUN_WORLD @ self._pose[k][:3, :3]                               # camera frame
        shade = MOCK_GREY * (AMBIENT + DIFFUSE * np.abs(n @ sun))
        rgb = np.where(np.isfinite(z)[..., None], shade[..., None], np.array(SKY_RGBA[:3]))
        out[..., :3] = np.clip(np.floor(rgb * 255.0 + 0.5), 0, 255).astype(np.uint8)
        out[..., 3] = 255

    def close(self) -> None:
        """Release the ray caster's scenes."""
        self._scene = None
        self.caster.close()
