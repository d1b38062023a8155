"""Dust for the cameras (``atmosphere:``; docs/cameras.md's post-process seam, docs/field.md): pure functions and
the effects of one camera (:class:`CameraDust`).

* **Contrast loss** (Koschmieder): a pixel seeing a surface at range d through dust of extinction alpha receives
  its radiance attenuated by ``t = exp(-alpha d)`` plus the airlight scattered into its ray,
  ``I = I0 t + A (1 - t)`` (A the dust's brightness, per channel; no surface: ``t = 0``). Where the camera has
  an exact depth image (the depth camera, with its colour image) d is each pixel's range; the stereo and colour
  cameras have none (the renderer writes only their colour images), so their images lose contrast as at the
  camera's typical working distance (``perception_proc.cameras.images.SIGMA_DISTANCE_M``), an approximation
  the docs state.
* **Speckle**: a lit dust grain closer to the lens than ``DUST_GRAIN_DIAMETER_M x f`` (f the focal length in
  pixels) covers a whole pixel, which then shows the airlight's brightness. A ray meets one there with
  probability ``1 - exp(-GEOMETRIC_SHARE alpha d_s)`` (large grains: half the extinction is their geometric
  shadow, half diffraction), drawn independently per pixel and image, seeded by (seed, frame, camera, image).
* **Invalid and false near depth** (the depth camera): each pixel's return competes with the dust's own
  backscatter as the LiDAR's beam does (:meth:`perception_proc.atmosphere.dust.DustModel.returns` on the pixel's
  exact range, with the camera's ``range_max_m`` as its detection limit): too weak a return leaves the pixel
  invalid, a stronger backscatter reports the dust's peak range; where the surface's return wins the camera's
  own measured depth stays.

The stereo matcher then fails where the images lost their texture: its invalid and wrong disparities come from
the matcher on degraded images, not from noise painted on the depth.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from cosim.scenario.config.cameras import DepthCamera
from cosim.scenario.config.scenario import Scenario
from cosim.world.sensors import camera_pinhole
from perception_proc.atmosphere.dust import DustModel, dust_blows, dust_model
from perception_proc.cameras.images import SIGMA_DISTANCE_M, CameraImages

__all__ = ["AIRLIGHT_RGB", "DUST_GRAIN_DIAMETER_M", "GEOMETRIC_SHARE", "DUST_CAMERA_STREAM", "transmission",
           "hazed", "speckle_share", "speckled", "dusty_depth", "speckle_generator", "CameraDust"]

#: the dust's brightness (0..255 per channel of an RGBA8 image): a light, brownish grey (an assumption: lit
#: mineral and plant dust; the renderer's lighting is not consulted)
AIRLIGHT_RGB = (200.0, 190.0, 170.0)
#: diameter of a harvest dust grain, m (an assumption: the coarse end of mineral and chaff dust)
DUST_GRAIN_DIAMETER_M = 50e-6
#: share of a large grain's extinction that is its geometric shadow (extinction efficiency 2: the other half is
#: diffraction)
GEOMETRIC_SHARE = 0.5
#: third seed word of the cameras' dust draws (apart from the depth noise and the LiDAR's streams)
DUST_CAMERA_STREAM = 0x44555354  # "DUST"


def speckle_generator(seed: int, frame: int, camera_index: int, image: int = 0) -> np.random.Generator:
    """The speckle draws of one image (0 left / colour, 1 right) of a camera's frame: seeded by (seed, frame,
    DUST_CAMERA_STREAM, camera index, image)."""
    return np.random.default_rng([int(seed), int(frame), DUST_CAMERA_STREAM, int(camera_index), int(image)])


def transmission(alpha: float, distance_m) -> np.ndarray:
    """One-way transmission ``exp(-alpha d)`` of dust of extinction ``alpha`` 1/m over ``distance_m`` m (NaN or
    inf: the sky, 0)."""
    d = np.asarray(distance_m, np.float64)
    with np.errstate(invalid="ignore", over="ignore"):
        return np.where(np.isfinite(d), np.exp(-alpha * np.maximum(np.nan_to_num(d), 0.0)), 0.0)


def hazed(rgba: np.ndarray, t) -> np.ndarray:
    """Koschmieder's ``I0 t + A (1 - t)`` on an (H, W, 4) uint8 image with transmission ``t`` (a number or
    (H, W)), rounded to the nearest level; the alpha channel kept. New array."""
    t = np.asarray(t, np.float64)
    t = t[..., None] if t.ndim == 2 else t
    rgb = rgba[..., :3].astype(np.float64) * t + np.asarray(AIRLIGHT_RGB) * (1.0 - t)
    out = rgba.copy()
    out[..., :3] = np.clip(np.rint(rgb), 0, 255).astype(np.uint8)
    return out


def speckle_share(alpha: float, f_px: float) -> float:
    """Probability that a pixel's ray meets a grain within ``DUST_GRAIN_DIAMETER_M f_px`` m of the lens (where
    one covers the pixel): ``1 - exp(-GEOMETRIC_SHARE alpha DUST_GRAIN_DIAMETER_M f_px)``."""
    return 1.0 - float(np.exp(-GEOMETRIC_SHARE * alpha * DUST_GRAIN_DIAMETER_M * f_px))


def speckled(rgba: np.ndarray, share: float, gen: np.random.Generator) -> np.ndarray:
    """Pixels of ``rgba`` (H, W, 4) uint8 covered by a lit grain (each with probability ``share``) turned to
    the airlight. New array."""
    hit = gen.random(rgba.shape[:2]) < share
    out = rgba.copy()
    out[hit, :3] = np.asarray(AIRLIGHT_RGB, np.uint8)
    return out


def dusty_depth(measured: np.ndarray, exact: np.ndarray, ray_length: np.ndarray, dust: DustModel) -> np.ndarray:
    """What a depth camera reports through ``dust``: its ``measured`` planar depth (H, W) float32 m (NaN
    invalid) where the surface's return wins at the exact planar depth ``exact`` (H, W) (NaN no surface), the
    dust's peak where its backscatter wins, NaN where nothing is detected (:meth:`DustModel.returns` on the
    ranges ``exact x ray_length``, ``ray_length`` (H, W) the ray's length per unit planar depth). New array."""
    r0 = (np.asarray(exact, np.float64) * ray_length).astype(np.float32)
    rep = dust.returns(r0.reshape(-1)).reshape(r0.shape)
    surface = np.isfinite(rep) & (rep == r0)
    out = np.where(surface, measured, rep / ray_length)
    return out.astype(np.float32)


class CameraDust:
    """The dust's effects on camera ``name`` of ``scenario`` (the seam's two stages, docs/cameras.md), for a
    scenario whose air has dust; outside ``atmosphere.dust_window_s`` both stages pass their input unchanged."""

    def __init__(self, scenario: Scenario, name: str):
        spec = scenario.cameras[name]
        self.scenario, self.seed = scenario, scenario.seed
        self.index = list(scenario.sensor_set).index(name)
        self.alpha = scenario.atmosphere.extinction_per_m
        pin = camera_pinhole(spec, scenario)
        self.share = speckle_share(self.alpha, pin.f)
        #: the typical transmission of a camera without a depth image
        self.t_typical = float(transmission(self.alpha, SIGMA_DISTANCE_M))
        self.dust = dust_model(scenario, spec.range_max_m) if isinstance(spec, DepthCamera) else None
        #: (H, W) the ray's length per unit planar depth
        self.ray_length = 1.0 / pin.ray_directions()[..., 2]

    def _blows(self, images: CameraImages) -> bool:
        return dust_blows(self.scenario.atmosphere, images.t_s)

    def images(self, images: CameraImages) -> CameraImages:
        """Haze and speckle on the colour images (``rgb``, ``right``); the depth image stays exact."""
        if (images.rgb is None and images.right is None) or not self._blows(images):
            return images
        if images.depth is not None:
            t = transmission(self.alpha, images.depth.astype(np.float64) * self.ray_length)
        else:
            t = self.t_typical
        out = {}
        for k, part in enumerate(("rgb", "right")):
            img = getattr(images, part)
            if img is not None:
                gen = speckle_generator(self.seed, images.frame, self.index, k)
                out[part] = speckled(hazed(img, t), self.share, gen)
        return replace(images, **out)

    def depth(self, images: CameraImages, depth_m: np.ndarray | None) -> np.ndarray | None:
        """The depth camera's measured depth through the dust (:func:`dusty_depth`); others unchanged."""
        if self.dust is None or depth_m is None or images.depth is None or not self._blows(images):
            return depth_m
        return dusty_depth(depth_m, images.depth, self.ray_length, self.dust)
