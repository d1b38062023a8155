"""The depth camera's noise models by name (``model`` of cosim.scenario.config.cameras.DepthCamera;
docs/cameras.md): ``structured_light`` (perception_proc.cameras.tof: Nguyen, Izadi and Lovell 2012, fitted to the
structured-light Kinect) and ``time_of_flight`` (perception_proc.cameras.time_of_flight: amplitude-dependent noise
and mixed pixels of a continuous-wave time-of-flight camera).

Each model is ``depth(z, pin, cam, gen) -> depth``: exact planar depth (H, W) float32 m (NaN no hit) of pinhole
``pin`` -> reported planar depth (H, W) float32 m (NaN invalid), ``gen`` the frame's generator or None (no noise).
:func:`normal_sigma_m` is a model's axial 1-sigma at normal incidence (what perception weighs and gates by).
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from cosim.scenario.config.cameras import DepthCamera
from perception_proc.cameras import time_of_flight
from perception_proc.cameras.tof import tof_depth

__all__ = ["DEPTH_MODEL_FUNCTIONS", "depth_model", "normal_sigma_m"]

#: model name -> its measurement function
DEPTH_MODEL_FUNCTIONS: dict[str, Callable] = {"structured_light": tof_depth,
                                              "time_of_flight": time_of_flight.time_of_flight_depth}


def depth_model(cam: DepthCamera) -> Callable:
    """The measurement function of ``cam.model``."""
    return DEPTH_MODEL_FUNCTIONS[cam.model]


def normal_sigma_m(cam: DepthCamera, z_m):
    """Axial 1-sigma (m) of ``cam``'s model at planar depth ``z_m`` (m, scalar or array) and normal incidence:
    structured light 0.0012 + 0.0019 (z - 0.4)^2 with the camera's coefficients; time of flight at range z on a
    surface of the camera's ``albedo``."""
    if cam.model == "time_of_flight":
        return time_of_flight.normal_sigma_m(cam, z_m)
    return cam.axial_a_m + cam.axial_b_per_m * (np.asarray(z_m, np.float64) - cam.axial_z0_m) ** 2
