"""Seeded random processes of the field conditions (docs/field.md): first-order Gauss-Markov processes.

A stationary Gauss-Markov process of standard deviation sigma and correlation time tau, sampled every dt, is the
AR(1) recursion

    x[k+1] = phi x[k] + sigma sqrt(1 - phi^2) w[k],    phi = exp(-dt / tau),  w[k] ~ N(0, 1) independent,

exact at the samples for the continuous process dx = -x / tau dt + sigma sqrt(2 / tau) dW: its variance is sigma^2
at every sample (it starts from a draw of the stationary distribution) and its autocorrelation at lag n dt is
sigma^2 phi^n = sigma^2 exp(-n dt / tau). It is the usual model of a GNSS receiver's slowly wandering position
error (RTK: about 2 cm, tens of seconds), of wheel slip and of a yield-driven flow variation.

Determinism: the draws of frame k of stream s come from their own generator,
``SeedSequence(seed, spawn_key=(FIELD_STREAM, s, k))``, so a frame's numbers depend on the scenario's seed, the
stream and the frame alone: the same scenario and seed give the same run, stepped in any process, and the
frame step stays a pure function of the world.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["FIELD_STREAM", "GNSS_STREAM", "SLIP_STREAM", "FLOW_STREAM", "gm_coefficients", "gm_start", "gm_step",
           "draws", "gm_series"]

#: spawn key of every field-condition stream (apart from the terrain's and the sensors')
FIELD_STREAM = 2
#: the streams: GNSS errors (4 draws a frame: combine x, y, tractor x, y), slip (1), flow variation (1)
GNSS_STREAM, SLIP_STREAM, FLOW_STREAM = 0, 1, 2


def gm_coefficients(sigma: float, tau_s: float, dt_s: float) -> tuple[float, float]:
    """(phi, q) of the AR(1) recursion ``x' = phi x + q w`` sampling a Gauss-Markov process of standard
    deviation ``sigma`` and correlation time ``tau_s`` every ``dt_s`` (s)."""
    phi = math.exp(-dt_s / tau_s)
    return phi, sigma * math.sqrt(max(1.0 - phi * phi, 0.0))


def draws(seed: int, stream: int, frame: int, n: int) -> np.ndarray:
    """The ``n`` standard normal draws of ``stream`` at ``frame`` (the module docstring), (n,) float64."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(FIELD_STREAM, stream, frame))).standard_normal(n)


def gm_start(sigma: float, w: np.ndarray) -> np.ndarray:
    """The process's first sample(s) from standard normal draws ``w``: a draw of the stationary distribution."""
    return sigma * np.asarray(w, np.float64)


def gm_step(x: np.ndarray, phi: float, q: float, w: np.ndarray) -> np.ndarray:
    """One AR(1) step from ``x`` with standard normal draws ``w`` (same shape)."""
    return phi * np.asarray(x, np.float64) + q * np.asarray(w, np.float64)


def gm_series(sigma: float, tau_s: float, dt_s: float, n: int, seed: int, stream: int = 0) -> np.ndarray:
    """``n`` successive samples (n,) of one process, drawn as the run draws them (first element of each frame's
    draws), for studies and tests."""
    phi, q = gm_coefficients(sigma, tau_s, dt_s)
    out = np.empty(n)
    out[0] = gm_start(sigma, draws(seed, stream, 0, 1))[0]
    for k in range(1, n):
        out[k] = gm_step(out[k - 1], phi, q, draws(seed, stream, k, 1))[0]
    return out
