"""The air between the sensors and what they see (``atmosphere:``; perception_proc.atmosphere.dust, docs/field.md).
Owned by perception_proc. Clear air (the default) changes nothing, to the bit."""
from __future__ import annotations

import math
from typing import Literal

from pydantic import Field

from .base import Model, NonNegFloat, PosFloat

__all__ = ["Atmosphere"]


class Atmosphere(Model):
    """Dust in the air and the grain stream as particles, for the LiDAR (the model of Hahner et al. 2021 for fog,
    with dust's constants; the stream after Hahner et al. 2022's snowfall); the dust also for the cameras (haze,
    speckle, a depth camera's pixels through the LiDAR's dust model; docs/cameras.md).

    * ``visibility_m``: meteorological optical range (MOR) of the dust, m; extinction alpha = ln(20) / MOR. Or
      ``dust_mass_g_m3`` with ``mass_extinction_m2_per_g``: alpha = mass x that. Both unset / 0: clear air;
    * ``dust_window_s``: the dust blows only over [start, end) s of the run (a gust), None all the time;
    * ``lidar_ratio_sr``: extinction-to-backscatter ratio of the dust, sr (backscatter beta = alpha / it; Saharan
      dust: 50 +- 5 sr at 532 nm, 63 +- 13 sr at 1064 nm, Haarig et al. 2022);
    * ``return_mode``: the return a LiDAR reports, the ``strongest`` or the ``last`` above its detection limit;
    * ``pulse_half_power_ns``: the pulse's half-power width (P0 sin^2(pi t / (2 tau)) over 2 tau);
    * ``overlap_m``: the receiver's field of view meets the beam from the first distance, fully from the second;
    * ``target_reflectivity``: Lambertian reflectivity of every hard target (the renderer gives ranges, not
      materials); ``detection_reflectivity``: the sensor detects a target of this reflectivity at its
      ``sensor.range_max_m`` (a depth camera: its own ``range_max_m``) in clear air and nothing weaker;
    * ``stream_particles``: the grain stream is no solid cylinder for the LiDAR but its kernels
      (``kernel_diameter_m``, reflectivity ``kernel_reflectivity``, ``packing_fraction`` of the stream's bulk
      volume), each occluding its share of a beam ``beam_divergence_mrad`` wide.
    """

    visibility_m: PosFloat | None = None
    """Meteorological optical range of the dust, m (None: from the mass concentration, or clear air)."""
    dust_mass_g_m3: NonNegFloat = 0.0
    """Dust mass concentration, g/m^3 (used when visibility_m is not given; 0: none)."""
    mass_extinction_m2_per_g: PosFloat = 0.5
    """Extinction per mass of the dust, m^2/g (mineral dust about 0.3-1; an assumption, see docs/field.md)."""
    dust_window_s: tuple[float, float] | None = None
    """The dust blows only from the first to the second time, s (None: all the run): a gust over the cart."""
    lidar_ratio_sr: PosFloat = 60.0
    """Extinction-to-backscatter ratio of the dust, sr."""
    return_mode: Literal["strongest", "last"] = "strongest"
    """The return the LiDAR reports."""
    pulse_half_power_ns: PosFloat = 20.0
    """Half-power width of the laser pulse, ns."""
    overlap_m: tuple[float, float] = (0.9, 1.0)
    """The receiver's field of view starts to meet the beam at the first range and fully at the second, m."""
    target_reflectivity: float = Field(default=0.3, gt=0.0, le=1.0, allow_inf_nan=False)
    """Lambertian reflectivity of the hard targets (grain, cart, ground)."""
    detection_reflectivity: float = Field(default=0.1, gt=0.0, le=1.0, allow_inf_nan=False)
    """A target of this reflectivity at sensor.range_max_m in clear air is the weakest return detected."""
    stream_particles: bool = False
    """The grain stream's kernels as partial occluders of the beams instead of a solid cylinder."""
    kernel_diameter_m: PosFloat = 0.008
    """Diameter of a grain kernel, m (corn about 8 mm)."""
    kernel_reflectivity: float = Field(default=0.4, gt=0.0, le=1.0, allow_inf_nan=False)
    """Lambertian reflectivity of a kernel."""
    packing_fraction: float = Field(default=0.6, gt=0.0, le=0.75, allow_inf_nan=False)
    """Solid share of the grain's bulk volume (what the flow in m^3/s is counted in)."""
    beam_divergence_mrad: PosFloat = 3.0
    """Full divergence of a beam, mrad (its footprint grows as that times the range)."""

    @property
    def extinction_per_m(self) -> float:
        """Extinction coefficient alpha of the dust, 1/m (0 in clear air)."""
        if self.visibility_m is not None:
            return math.log(20.0) / self.visibility_m
        return self.mass_extinction_m2_per_g * self.dust_mass_g_m3

    @property
    def clear(self) -> bool:
        """Whether the LiDAR sees as in clear air with a solid stream (then nothing is applied)."""
        return self.extinction_per_m == 0.0 and not self.stream_particles
