"""Scenario section for the renderer. Owned by renderer_proc (issue 4)."""
from __future__ import annotations

from typing import Literal

from pydantic import Field

from .base import Model, PosFloat

__all__ = ["Render"]


class Render(Model):
    """Renderer options. The camera rig is planned from the LiDAR pattern unless ``cameras`` fixes it.

    ``rgb``: ``auto`` renders the shaded image only when something consumes it (a viewer or recorder).
    """

    rig: Literal["auto", "fixed"] = "auto"
    cameras: int = Field(default=2, ge=1, le=16)
    width_px: int = Field(default=640, ge=8, le=8192)
    height_px: int = Field(default=480, ge=8, le=8192)
    hfov_deg: float = Field(default=60.0, gt=1.0, lt=170.0)
    rgb: Literal["auto", "on", "off"] = "auto"
    float_depth: bool = False
    mock_scale: PosFloat = 1.0
    ground_size_m: PosFloat = 400.0
