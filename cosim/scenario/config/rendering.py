"""Scenario section for the renderer. Owned by renderer_proc."""
from __future__ import annotations

from typing import Literal

from pydantic import Field

from .base import Model, PosFloat

__all__ = ["Render"]


class Render(Model):
    """Renderer options. The camera rig is planned from the LiDAR pattern unless ``rig`` is ``fixed``.

    * ``rig``: ``auto`` plans the fewest cameras (then the fewest pixels) that cover ``sensor.pattern`` with a
      nearest-pixel angular error <= ``sensor.max_angular_error_deg`` (``cosim.world.rig``); ``fixed`` uses
      ``cameras`` cameras of ``width_px`` x ``height_px`` and ``hfov_deg``, side by side in yaw.
    * ``rgb``: ``auto`` renders the shaded image only when something consumes it (a viewer); ``on`` always;
      ``off`` never.
    * ``float_depth``: also write each camera's exact float32 planar depth (``<cam>_zf``).
    * ``mock_scale``: resolution factor of the rig when ``renderer`` is ``mock`` (the numpy ray caster costs
      about 5 us per pixel: the default rig at full size would take seconds per frame). The image blocks and
      perception follow the scaled rig.
    * ``ground_size_m``: side of the square ground plane, centred under the combine.
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
    """Resolution factor of the rig with the mock renderer (0-1]; images and perception follow the scaled rig."""
    ground_size_m: PosFloat = 400.0
    """Side of the square ground plane, centred under the combine, m."""
