"""Which sensors enter the fusion (docs/cameras.md, "Each camera's own expected error"): a depth camera whose
expected error of a cell's height at the found cart is more than the fill target allows is left out while a fit
sensor is left, and the height map is withheld only when none is.

A LiDAR is fit (the gate has no expected-error model for it); a depth camera is fit in a frame where it sees the
cart and :data:`perception_proc.cameras.expected.FIT_SIGMAS` of its cell 1-sigma are within the overfill
tolerance, unfit where they are not, and undecided where it does not see the found cart (it keeps its last
verdict). :class:`FusionSelection` holds the verdicts between frames: a camera judged unfit is left out of the
next frames' fusion (and of the frame that judged it, which is perceived again without it) until it is judged
fit again; perception's log says why, once per camera (and, once, that it is fused again).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Mapping, Sequence

from perception_proc.cameras.expected import FIT_SIGMAS

__all__ = ["CameraFit", "FusionSelection", "judge", "unfit_reason"]

log = logging.getLogger("cosim.perception")


@dataclass(frozen=True)
class CameraFit:
    """One camera's verdict in one frame: ``sigma_m`` the expected 1-sigma of a cell's height at the cart (m),
    ``depth_m`` the planar depth at which it sees the cart (m), ``unfit`` when FIT_SIGMAS sigmas exceed the
    overfill tolerance ``tolerance_m`` (m); ``basis`` what the figure rests on."""

    sigma_m: float
    depth_m: float
    tolerance_m: float
    #: what the figure rests on (perception_proc.cameras.expected.error_basis)
    basis: str = ""

    @property
    def unfit(self) -> bool:
        return self.sigma_m * FIT_SIGMAS > self.tolerance_m


def judge(sigmas: Mapping[str, tuple[float, float]], tolerance_m: float,
          basis: Mapping[str, str] | None = None) -> dict[str, CameraFit]:
    """The verdicts of the cameras that see the cart: ``sigmas`` name -> (sigma m, depth m)
    (perception_proc.cameras.sensors.PerceptionCameras.sigmas_at_cart); ``tolerance_m`` the overfill
    tolerance (m); ``basis`` name -> what each camera's figure rests on."""
    basis = basis or {}
    return {n: CameraFit(s, z, tolerance_m, basis.get(n, "")) for n, (s, z) in sigmas.items()}


def unfit_reason(name: str, fit: CameraFit) -> str:
    """The sentence naming camera ``name``'s figure against what the target allows."""
    allowed = fit.tolerance_m / FIT_SIGMAS
    return (f"camera {name}: expected error of a cell's height at the cart {100 * fit.sigma_m:.1f} cm at "
            f"{fit.depth_m:.1f} m{f' ({fit.basis})' if fit.basis else ''}, more than the {100 * allowed:.1f} cm "
            f"the {100 * fit.tolerance_m:.0f} cm overfill tolerance allows")


@dataclass
class FusionSelection:
    """The cameras left out of the fusion, between frames. ``has_lidar``: a LiDAR is fused (always fit)."""

    has_lidar: bool
    #: camera name -> why it is left out
    dropped: dict[str, str] = field(default_factory=dict)
    _logged: set = field(default_factory=set)

    def fused(self, cameras: Sequence[tuple]) -> list[tuple]:
        """The (SensorFrame, border) pairs of the cameras not left out."""
        return [(f, b) for f, b in cameras if f.name not in self.dropped]

    def fit_left(self, fits: Mapping[str, CameraFit]) -> bool:
        """Whether a fit sensor sees the cart in this frame's verdicts ``fits`` (or a LiDAR is fused)."""
        return self.has_lidar or any(not f.unfit for f in fits.values())

    def update(self, fits: Mapping[str, CameraFit]) -> bool:
        """Take this frame's verdicts ``fits``; True when a camera that was fused this frame is now left out
        (the frame is to be perceived again without it). Where no fit sensor is left nothing is left out: the
        caller withholds the height map."""
        if not self.fit_left(fits):
            return False
        again = False
        for name, fit in fits.items():
            if fit.unfit and name not in self.dropped:
                self.dropped[name] = unfit_reason(name, fit)
                again = True
                if name not in self._logged:
                    self._logged.add(name)
                    log.warning("%s: left out of the fusion, the fit sensors are fused", self.dropped[name])
            elif not fit.unfit and name in self.dropped:
                del self.dropped[name]
                if ("fit", name) not in self._logged:
                    self._logged.add(("fit", name))
                    log.info("camera %s: fit again (%.1f cm at %.1f m), fused", name, 100 * fit.sigma_m, fit.depth_m)
        return again
