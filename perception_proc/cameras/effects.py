"""The per-camera post-process seam (docs/cameras.md): what happens to a camera's signal between the renderer's
ideal images and the depth and points perception uses.

``camera_effects(scenario, name)`` returns the effects of camera ``name``: an object with two stages,

* ``images(images: CameraImages) -> CameraImages``: on the rendered images before the sensor's model (the
  colour images the stereo matcher sees, the exact depth the depth camera's model starts from): where
  field conditions change what reaches the sensor (dust: contrast loss and speckle on the colour images);
* ``depth(images: CameraImages, depth_m) -> depth_m``: on the measured depth (H, W) float32 m (NaN invalid),
  after the model, with the exact images at hand (dust: the depth camera's invalid or false near depths).

Both stages must be pure functions of their inputs and, for anything random, of a generator seeded from the
scenario seed, the frame (``images.frame``) and the camera, and for anything varying in time of the images'
``t_s``: a run stays byte-identical. Clear air changes nothing (``NoEffects``); dust in ``atmosphere:``
plugs in ``perception_proc.atmosphere.camera``.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

import numpy as np

from cosim.scenario.config.scenario import Scenario
from perception_proc.atmosphere.camera import CameraDust

if TYPE_CHECKING:
    from perception_proc.cameras.images import CameraImages

__all__ = ["CameraEffects", "NoEffects", "camera_effects"]


class CameraEffects(Protocol):
    """The two stages of a camera's post-process (module docstring)."""

    def images(self, images: "CameraImages") -> "CameraImages": ...

    def depth(self, images: "CameraImages", depth_m: np.ndarray) -> np.ndarray: ...


class NoEffects:
    """The ideal camera: both stages return their input unchanged."""

    def images(self, images: "CameraImages") -> "CameraImages":
        return images

    def depth(self, images: "CameraImages", depth_m: np.ndarray) -> np.ndarray:
        return depth_m


def camera_effects(scenario: Scenario, name: str) -> CameraEffects:
    """The effects camera ``name`` of ``scenario`` sees: the dust of ``atmosphere:``
    (:class:`perception_proc.atmosphere.camera.CameraDust`) when the air has any, else none (:class:`NoEffects`: clear
    air changes nothing, to the bit)."""
    if scenario.atmosphere.extinction_per_m == 0.0:
        return NoEffects()
    return CameraDust(scenario, name)
