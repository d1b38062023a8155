"""The air between the sensors and what they see (``atmosphere:``; perception_proc.atmosphere.dust, docs/field.md).
Owned by perception_proc. Clear air (the default) changes nothing, to the bit."""
from __future__ import annotations

import math
from typing import Literal

from pydantic import Field, model_validator

from .base import Model
from .limits import key_error

__all__ = ["Atmosphere", "MIN_VISIBILITY_M", "MAX_DUST_G_M3", "MAX_MASS_EXTINCTION_M2_PER_G", "KERNEL_DIAMETER_M",
           "LIDAR_RATIO_SR", "PULSE_HALF_POWER_NS", "MAX_BEAM_DIVERGENCE_MRAD"]

#: shortest meteorological optical range, m: the densest dust a sensor of this platform is modelled in (a
#: haboob's wall or a rotorcraft's brown-out bring visibility to a few metres; below 1 m every sensor sees only
#: its own housing). A mass concentration is held to the extinction this range gives (ln 20 / 1 m = 3.0 / m).
MIN_VISIBILITY_M = 1.0
#: largest dust mass concentration, g/m^3: the minimum explosible concentration of grain dust (about 50 g/m^3,
#: NFPA 61 / Eckhoff, Dust Explosions in the Process Industries); denser air is an explosion hazard, not a field
MAX_DUST_G_M3 = 50.0
#: largest mass extinction efficiency, m^2/g: fine mineral dust reaches about 1-3 m^2/g at visible and
#: near-infrared wavelengths (Hand and Malm 2007); 10 is a generous ceiling
MAX_MASS_EXTINCTION_M2_PER_G = 10.0
#: (smallest, largest) grain kernel diameter, m: 0.5 mm (small seeds: teff, alfalfa 1-2 mm) to 30 mm (larger
#: than a faba bean, about 25 mm); corn is about 8 mm
KERNEL_DIAMETER_M = (0.0005, 0.03)
#: (smallest, largest) extinction-to-backscatter ratio, sr: published aerosol lidar ratios lie in 10-120 sr
#: (Saharan dust 50-65 sr, Haarig et al. 2022; smoke up to about 100 sr); 1-200 leaves room on both sides
LIDAR_RATIO_SR = (1.0, 200.0)
#: (shortest, longest) half-power pulse width, ns: automotive and survey LiDARs fire 1-100 ns pulses
PULSE_HALF_POWER_NS = (0.1, 1000.0)
#: widest beam, mrad: LiDAR beams diverge 0.1-10 mrad; 100 mrad (5.7 deg) is a floodlight, not a beam
MAX_BEAM_DIVERGENCE_MRAD = 100.0


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

    visibility_m: float | None = Field(default=None, ge=MIN_VISIBILITY_M, allow_inf_nan=False)
    """Meteorological optical range of the dust, m, at least 1 m (None: from the mass concentration, or clear
    air). Give this or dust_mass_g_m3, not both."""
    dust_mass_g_m3: float = Field(default=0.0, ge=0.0, le=MAX_DUST_G_M3, allow_inf_nan=False)
    """Dust mass concentration, g/m^3, at most 50 (grain dust's minimum explosible concentration); 0: none. Give
    this or visibility_m, not both."""
    mass_extinction_m2_per_g: float = Field(default=0.5, gt=0.0, le=MAX_MASS_EXTINCTION_M2_PER_G,
                                            allow_inf_nan=False)
    """Extinction per mass of the dust, m^2/g, at most 10 (mineral dust about 0.3-1; an assumption, see
    docs/field.md)."""
    dust_window_s: tuple[float, float] | None = None
    """The dust blows only from the first to the second time, s (None: all the run): a gust over the cart; the
    start at least 0 and before the end."""
    lidar_ratio_sr: float = Field(default=60.0, ge=LIDAR_RATIO_SR[0], le=LIDAR_RATIO_SR[1], allow_inf_nan=False)
    """Extinction-to-backscatter ratio of the dust, sr (1-200; published aerosol ratios lie in 10-120)."""
    return_mode: Literal["strongest", "last"] = "strongest"
    """The return the LiDAR reports."""
    pulse_half_power_ns: float = Field(default=20.0, ge=PULSE_HALF_POWER_NS[0], le=PULSE_HALF_POWER_NS[1],
                                       allow_inf_nan=False)
    """Half-power width of the laser pulse, ns (0.1-1000)."""
    overlap_m: tuple[float, float] = (0.9, 1.0)
    """The receiver's field of view starts to meet the beam at the first range and fully at the second, m (0 <=
    first <= second)."""
    target_reflectivity: float = Field(default=0.3, gt=0.0, le=1.0, allow_inf_nan=False)
    """Lambertian reflectivity of the hard targets (grain, cart, ground)."""
    detection_reflectivity: float = Field(default=0.1, gt=0.0, le=1.0, allow_inf_nan=False)
    """A target of this reflectivity at sensor.range_max_m in clear air is the weakest return detected."""
    stream_particles: bool = False
    """The grain stream's kernels as partial occluders of the beams instead of a solid cylinder."""
    kernel_diameter_m: float = Field(default=0.008, ge=KERNEL_DIAMETER_M[0], le=KERNEL_DIAMETER_M[1],
                                     allow_inf_nan=False)
    """Diameter of a grain kernel, m (corn about 8 mm; 0.5-30 mm, from the smallest seeds to beyond a faba
    bean)."""
    kernel_reflectivity: float = Field(default=0.4, gt=0.0, le=1.0, allow_inf_nan=False)
    """Lambertian reflectivity of a kernel."""
    packing_fraction: float = Field(default=0.6, gt=0.0, le=0.75, allow_inf_nan=False)
    """Solid share of the grain's bulk volume (what the flow in m^3/s is counted in)."""
    beam_divergence_mrad: float = Field(default=3.0, gt=0.0, le=MAX_BEAM_DIVERGENCE_MRAD, allow_inf_nan=False)
    """Full divergence of a beam, mrad (its footprint grows as that times the range; at most 100)."""

    @model_validator(mode="after")
    def _consistent(self) -> "Atmosphere":
        """One of the two dust keys, intervals in order, and the extinction of a mass within that of the densest
        dust (:data:`MIN_VISIBILITY_M`); each refused at the key to change."""
        if self.visibility_m is not None and self.dust_mass_g_m3 > 0.0:
            raise key_error("Atmosphere", ("dust_mass_g_m3",), "give visibility_m or dust_mass_g_m3, not both: "
                            f"visibility_m ({self.visibility_m:g} m) would count and dust_mass_g_m3 be ignored; "
                            "remove one", self.dust_mass_g_m3)
        densest = math.log(20.0) / MIN_VISIBILITY_M
        if self.visibility_m is None and self.extinction_per_m > densest:
            raise key_error("Atmosphere", ("dust_mass_g_m3",), f"{self.dust_mass_g_m3:g} g/m^3 x "
                            f"{self.mass_extinction_m2_per_g:g} m^2/g is an extinction of {self.extinction_per_m:.3g}"
                            f" /m, a visibility of {math.log(20.0) / self.extinction_per_m:.3g} m; at most "
                            f"{densest:.3g} /m (a visibility of {MIN_VISIBILITY_M:g} m)", self.dust_mass_g_m3)
        for key, (lo, hi), what in (("dust_window_s", self.dust_window_s or (0.0, 1.0), "s"),
                                    ("overlap_m", self.overlap_m, "m")):
            if lo < 0.0:
                raise key_error("Atmosphere", (key, 0), f"the start {lo:g} {what} must be at least 0", lo)
            if hi < lo if key == "overlap_m" else hi <= lo:
                order = "at least" if key == "overlap_m" else "after"
                raise key_error("Atmosphere", (key, 1), f"the end {hi:g} {what} must be {order} the start "
                                f"{lo:g} {what} (a [start, end] interval)", hi)
        return self

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
