"""The time-of-flight depth camera's measurement model (``model: time_of_flight``, docs/cameras.md): exact rendered
depth -> what a continuous-wave time-of-flight camera reports. Pure functions, seeded per frame.

A continuous-wave time-of-flight pixel measures the phase of the returned modulated light; its range noise is
(Lange and Seitz 2001, "Solid-state time-of-flight range camera", IEEE J. Quantum Electron. 37(3), Eq. 9)
sigma = L / sqrt(8) sqrt(B) / (c_d A): A the returned amplitude, B the offset (the signal's own light plus the
background's), both in electrons. The amplitude of a diffuse surface of reflectance ``albedo`` at range r seen at
incidence theta is A ~ albedo cos(theta) / r^2 (:func:`amplitude`, relative units). Written against a reference
return A_ref (a ``tof_ref_albedo`` surface at ``tof_ref_range_m`` facing the camera, whose 1-sigma the datasheet
states, ``tof_ref_sigma_m``) with q = A_ref / A, the variance is the signal's shot noise (~ 1 / A) plus the
background's (~ 1 / A^2):

    sigma(q) = tof_ref_sigma_m sqrt(s q + (1 - s) q^2),    s = ``tof_signal_share``      (:func:`tof_sigma_m`)

Mixed pixels: a pixel whose footprint straddles a depth edge (its 3 x 3 neighbourhood spans more than
``flying_edge_m``, ``tof.flying_mask``) sums the two returns as phasors; for phase differences well under half a
turn the phase of the sum is the amplitude-weighted mean of the two depths (:func:`mixed_depth`), a share w of the
footprint on the nearer surface drawn uniform in [0, 1]. Both surfaces take the pixel's albedo and incidence, so
their amplitude ratio is the inverse square of their depths on the pixel's ray; a miss behind (no return) leaves
the near return alone, at its share of the amplitude. Each pixel measures its own ray: there is no lateral
displacement. The noise is along the ray (range); the planar depth's is it divided by the ray's length per unit
depth (:func:`ray_length_factor`). Pixels beyond ``max_incidence_deg`` or outside ``range_min_m`` .. ``range_max_m`` or with no hit are
invalid (NaN). ``multipath: true`` adds each pixel's one-bounce diffuse multipath range bias
(perception_proc.cameras.multipath: a concave scene such as a cart's inside reads farther) before the noise. Not
modelled: phase wrapping beyond the unambiguous range, the systematic wiggling error.
"""
from __future__ import annotations

import functools
import math

import numpy as np

from cosim.scenario.config.cameras import DepthCamera
from cosim.world.camera import Pinhole
from perception_proc.cameras.multipath import pixel_range_bias
from perception_proc.cameras.tof import flying_mask, incidence

__all__ = ["ray_length_factor", "amplitude", "reference_amplitude", "tof_sigma_m", "normal_sigma_m", "mixed_depth",
           "time_of_flight_depth"]


def ray_length_factor(pin: Pinhole) -> np.ndarray:
    """(H, W) float64: each pixel's range per unit planar depth, sqrt(1 + x^2 + y^2) of its normalised ray."""
    uu, vv = pin.pixel_centres()
    x = (uu - pin.width / 2.0) / pin.f
    y = (pin.height / 2.0 - vv) / pin.f
    return np.sqrt(1.0 + x * x + y * y)


@functools.lru_cache(maxsize=8)
def _ray_length_factor(pin: Pinhole) -> np.ndarray:
    """:func:`ray_length_factor` of ``pin``, made once per pinhole (read-only)."""
    k = ray_length_factor(pin)
    k.flags.writeable = False
    return k


def amplitude(range_m: np.ndarray, theta: np.ndarray, albedo: float) -> np.ndarray:
    """Relative returned amplitude albedo cos(theta) / r^2 (1 / m^2) at range ``range_m`` (m) and incidence
    ``theta`` (rad), arrays of one shape."""
    with np.errstate(invalid="ignore", divide="ignore"):
        return albedo * np.cos(theta) / (range_m * range_m)


def reference_amplitude(cam: DepthCamera) -> float:
    """The reference return's relative amplitude, ``tof_ref_albedo / tof_ref_range_m^2`` (1 / m^2)."""
    return cam.tof_ref_albedo / (cam.tof_ref_range_m * cam.tof_ref_range_m)


def tof_sigma_m(amp: np.ndarray, cam: DepthCamera) -> np.ndarray:
    """Axial 1-sigma (m) of returns of relative amplitude ``amp`` (1 / m^2, any shape): the module's law."""
    with np.errstate(invalid="ignore", divide="ignore"):
        q = reference_amplitude(cam) / np.asarray(amp, np.float64)
    s = cam.tof_signal_share
    return cam.tof_ref_sigma_m * np.sqrt(s * q + (1.0 - s) * q * q)


def normal_sigma_m(cam: DepthCamera, range_m):
    """Axial 1-sigma (m) of a surface of the camera's ``albedo`` facing it at range ``range_m`` (m, any shape)."""
    r = np.asarray(range_m, np.float64)
    return tof_sigma_m(cam.albedo / (r * r), cam)


def mixed_depth(near: np.ndarray, far: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The mixed return of a pixel with share ``w`` of its footprint on depth ``near`` and ``1 - w`` on ``far``
    (m; ``far`` NaN: no return there): (depth (m), amplitude relative to the near surface's alone). The weights
    are the shares times amplitudes ~ 1 / depth^2 on one ray: the depth is (w / n + (1 - w) / f) / (w / n^2 +
    (1 - w) / f^2), between ``near`` and ``far``."""
    with np.errstate(invalid="ignore", divide="ignore"):
        a_far = np.where(np.isfinite(far), (near / far) ** 2, 0.0)
        f = np.where(np.isfinite(far), far, near)
        weight = w + (1.0 - w) * a_far
        depth = (w * near + (1.0 - w) * a_far * f) / weight
    return depth, weight


def time_of_flight_depth(z: np.ndarray, pin: Pinhole, cam: DepthCamera, gen: np.random.Generator | None
                         ) -> np.ndarray:
    """The time-of-flight camera's reported planar depth (H, W) float32 m, NaN invalid, from the exact planar
    depth ``z`` (H, W) float32 (NaN no hit) of pinhole ``pin``. ``gen`` None (or ``cam.noise`` false): exact
    depth within the limits, no noise."""
    z = np.asarray(z, np.float64)
    theta = incidence(pin, z)
    out = z.copy()
    if gen is not None and cam.noise:
        h, w = z.shape
        k = _ray_length_factor(pin)
        with np.errstate(invalid="ignore", divide="ignore"):
            lit = cam.albedo * np.cos(np.nan_to_num(theta, nan=0.0))   # :func:`amplitude`'s numerator, both returns'
            r = z * k
            amp = lit / (r * r)
        fly, near, far = flying_mask(z, cam.flying_edge_m)
        share = gen.random((h, w))
        # the mixed return on the edge pixels only (elementwise, so the same numbers as over the whole image): its
        # depth, and its amplitude as the share-weighted sum, the near surface's amplitude scaled by the weight
        mixed, weight = mixed_depth(near[fly], far[fly], share[fly])
        out[fly] = mixed
        with np.errstate(invalid="ignore", divide="ignore"):
            r_near = near[fly] * k[fly]
            amp[fly] = lit[fly] / (r_near * r_near) * weight
        if cam.multipath:
            out = out + pixel_range_bias(pin, z, cam.albedo) / k                  # range bias, as planar depth
        out = out + gen.standard_normal((h, w)) * (tof_sigma_m(amp, cam) / k)     # range noise, as planar depth
    with np.errstate(invalid="ignore"):
        bad = ~np.isfinite(out) | (out < cam.range_min_m) | (out > cam.range_max_m) | (
            theta > math.radians(cam.max_incidence_deg))
    out[bad] = np.nan
    return out.astype(np.float32)
