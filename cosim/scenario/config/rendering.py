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
    cameras: int = Field(default=2, ge=1, le=16)
    width_px: int = Field(default=640, ge=8, le=8192)
    height_px: int = Field(default=480, ge=8, le=8192)
    hfov_deg: float = Field(default=60.0, gt=1.0, lt=170.0)
    rgb: Literal["auto", "on", "off"] = "auto"
    float_depth: bool = False
    mock_scale: float = Field(default=0.25, gt=0.0, le=1.0, allow_inf_nan=False)
    ground_size_m: PosFloat = 400.0
