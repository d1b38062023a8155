"""Scenario section for the renderer. Owned by renderer_proc."""
from __future__ import annotations

from typing import Literal

from pydantic import Field

from .base import Fraction, Model, Mount, PosFloat

__all__ = ["Render", "Lighting", "WorkLight"]


class WorkLight(Model):
    """A work light on a machine: a point light at ``mount`` (its position is what counts) whose irradiance
    falls off as 1 / r^2; ``intensity`` is the irradiance it gives at 1 m, in units of the full sun's (after
    the cameras' exposure: at night a camera exposes for its work light)."""

    mount: Mount = Mount(parent="combine", xyz_m=(-2.0, 5.5, 4.9))
    """Where the light is (its position; on the auger by default)."""
    intensity: PosFloat = 12.0
    """Irradiance at 1 m, in units of the full sun's (falls off as 1 / r^2)."""


class Lighting(Model):
    """Light for the cameras' colour images (docs/cameras.md): the sun at ``sun_elevation_deg`` above the
    horizon and ``sun_azimuth_deg`` from world +x (the harvest direction) towards +y (left); ``ambient`` is the
    sky's share of the light on a surface facing up. With the sun at or below the horizon it is night: no sun,
    ``night_ambient`` of sky glow, and the ``work_light`` (when given) is the light there is. The depth
    images and the LiDAR do not depend on it."""

    sun_elevation_deg: float = Field(default=60.0, ge=-90.0, le=90.0, allow_inf_nan=False)
    """Sun above the horizon, deg (at or below 0: night)."""
    sun_azimuth_deg: float = Field(default=53.13, ge=-360.0, le=360.0, allow_inf_nan=False)
    """Sun's direction from world +x (the harvest direction) towards +y (left), deg."""
    ambient: Fraction = 0.35
    """The sky's share of the light by day."""
    night_ambient: Fraction = 0.02
    """The sky glow at night."""
    work_light: WorkLight | None = None
    """A work light on a machine (the light there is at night)."""

    @property
    def night(self) -> bool:
        """Whether the sun is at or below the horizon."""
        return self.sun_elevation_deg <= 0.0


class Render(Model):
    """Renderer options. The camera rig is planned from the LiDAR pattern unless ``rig`` is ``fixed``.

    * ``rig``: ``auto`` plans the fewest cameras (then the fewest pixels) that cover ``sensor.pattern`` with a
      nearest-pixel angular error <= ``sensor.max_angular_error_deg`` (``cosim.world.rig``); ``fixed`` uses
      ``cameras`` cameras of ``width_px`` x ``height_px`` and ``hfov_deg``, side by side in yaw.
    * ``rgb``: ``auto`` renders the shaded image only when something consumes it (a viewer); ``on`` always;
      ``off`` never.
    * ``float_depth``: also write each camera's exact float32 planar depth (``<cam>_zf``).
    * ``mock_scale``: resolution factor of the rig, and of colour and stereo cameras, when ``renderer`` is ``mock``
      (the numpy ray caster costs about 5 us per pixel: the default rig at full size would take seconds per
      frame). The image blocks and perception follow the scaled rig. A depth camera keeps its own size (its
      error model is per pixel of the device).
    * ``ground_size_m``: side of the square ground plane, centred under the combine.
    * ``lighting``: the sun (or night and a work light) for the cameras' colour images (:class:`Lighting`).
    """

    rig: Literal["auto", "fixed"] = "auto"
    """auto: the fewest cameras (then pixels) that cover the beam pattern within sensor.max_angular_error_deg;
    fixed: cameras x width_px x height_px with hfov_deg."""
    cameras: int = Field(default=2, ge=1, le=16)
    """Cameras of a fixed rig, side by side in yaw (1-16)."""
    width_px: int = Field(default=640, ge=8, le=8192)
    """Image width of a fixed rig's camera, px."""
    height_px: int = Field(default=480, ge=8, le=8192)
    """Image height of a fixed rig's camera, px."""
    hfov_deg: float = Field(default=60.0, gt=1.0, lt=170.0)
    """Horizontal field of view of a fixed rig's camera, deg."""
    rgb: Literal["auto", "on", "off"] = "auto"
    """auto: render the shaded image only when something consumes it (a viewer); on: always; off: never."""
    float_depth: bool = False
    """Also write each camera's exact float32 planar depth."""
    mock_scale: float = Field(default=0.25, gt=0.0, le=1.0, allow_inf_nan=False)
    """Resolution factor of the rig, and of colour and stereo cameras, with the mock renderer (0-1]; images and
    perception follow the scaled rig; a depth camera keeps its own size."""
    ground_size_m: PosFloat = 400.0
    """Side of the square ground plane, centred under the combine, m."""
    lighting: Lighting = Lighting()
    """Light for the camera sensors' colour images: the sun, or night with a work light."""
