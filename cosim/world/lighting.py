"""The light of the cameras' colour images (docs/cameras.md; ``render.lighting``): pure functions of the scenario
record, used by the GL camera renderer and the mock alike."""
from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from cosim.scenario.config.rendering import Lighting
from cosim.world.sensors import world_from_parent

__all__ = ["sun_direction", "work_light_world", "irradiance"]


def sun_direction(lighting: Lighting) -> np.ndarray:
    """Unit vector towards the sun (3,) float64, world frame: elevation above the horizon, azimuth from +x
    towards +y. Below the horizon it still points at the sun (the renderers then give it no light)."""
    e, a = math.radians(lighting.sun_elevation_deg), math.radians(lighting.sun_azimuth_deg)
    return np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])


def work_light_world(lighting: Lighting, state: Mapping[str, float]) -> np.ndarray | None:
    """The work light's position (3,) float64, world m, at the dynamics state ``state``; None without one."""
    wl = lighting.work_light
    if wl is None:
        return None
    return (world_from_parent(wl.mount.parent, state) @ np.array([*wl.mount.xyz_m, 1.0]))[:3]


def irradiance(normal: np.ndarray, point: np.ndarray, lighting: Lighting, sun: np.ndarray,
               light: np.ndarray | None) -> np.ndarray:
    """Light falling on surfaces, in units of the full sun's irradiance on a surface facing it: the sky's
    ``ambient`` (``night_ambient`` at night) plus the sun's Lambert term (by day) plus the work light's,
    ``intensity cos / r^2`` (when ``light``, its world position, is given). ``normal`` (..., 3) unit and
    ``point`` (..., 3) m, world frame; ``sun`` (3,) from :func:`sun_direction`. Two-sided: a surface is lit
    from whichever side faces the light (the camera sees the lit side of thin parts). Returns (...,)."""
    n = np.asarray(normal, np.float64)
    out = np.full(n.shape[:-1], lighting.night_ambient if lighting.night else lighting.ambient)
    if not lighting.night:
        out += (1.0 - lighting.ambient) * np.abs(n @ sun)
    if light is not None and lighting.work_light is not None:
        to = light - np.asarray(point, np.float64)
        r2 = np.maximum(np.einsum("...i,...i->...", to, to), 1e-6)
        out += lighting.work_light.intensity * np.abs(np.einsum("...i,...i->...", n, to)) / r2 ** 1.5
    return out
