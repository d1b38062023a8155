"""Depth-in-colour codec of the paper's Eqs 1-2: the numpy reference encoder (docs/CONTRACTS.md).

The GL fragment shader (``shaders/encode.frag``) computes exactly these bytes; this module is the reference the
mock renderer uses and the GL tests compare against. Decoding (Eq 3) lives in perception_proc and is written
independently; :func:`decode_depth` here is only a test oracle for the encoder.

Conventions: ``d`` is planar camera Z in cm. x_R = min(d / alpha, 1), x_B = (d mod beta) / beta.

* ``gamma_mode == "linear"``: the paper's shader writes x^gamma and the engine's inverse gamma undoes it before
  8-bit storage, so the stored bytes are linear: R = G = round(255 x_R), B = round(255 x_B).
* ``gamma_mode == "mishandled"``: nothing undoes the gamma, the bytes are quantised in the gamma domain:
  R = G = round(255 x_R^gamma), B = round(255 x_B^gamma).

A = 255 marks a valid hit; background (no hit, non-finite depth), d <= 0 and d >= alpha (out of range) get
A = 0 and R = G = B = 0: such pixels never carry a depth.
"""
from __future__ import annotations

import numpy as np

from cosim.scenario.config.sensing import Codec

__all__ = ["BYTE_MAX", "CM_PER_M", "VALID_ALPHA", "decode_depth", "encode_depth", "valid_depth_mask"]

#: centimetres per metre (the codec works in cm, the platform in m)
CM_PER_M = 100.0
#: largest 8-bit channel value
BYTE_MAX = 255
#: alpha byte of a valid pixel (0 marks invalid)
VALID_ALPHA = 255


def valid_depth_mask(depth_m: np.ndarray, codec: Codec) -> np.ndarray:
    """Pixels that carry a depth: finite, > 0 and < alpha. ``depth_m`` any shape, m; returns bool, same shape."""
    d = np.asarray(depth_m, dtype=np.float64)
    with np.errstate(invalid="ignore"):     # NaN and +-inf fail one of the two comparisons
        return (d > 0.0) & (d * CM_PER_M < codec.alpha_cm)


def encode_depth(depth_m: np.ndarray, codec: Codec, out: np.ndarray | None = None) -> np.ndarray:
    """Encode planar depth into RGBA8 bytes (Eqs 1-2).

    ``depth_m``: (H, W) planar camera Z in m (float; inf or NaN for no hit). ``out``: optional (H, W, 4) uint8
    destination (e.g. a shared-memory image view), filled in place. Returns the (H, W, 4) uint8 image.
    """
    d_m = np.asarray(depth_m, dtype=np.float64)
    if out is None:
        out = np.empty(d_m.shape + (4,), dtype=np.uint8)
    elif out.shape != d_m.shape + (4,) or out.dtype != np.uint8:
        raise ValueError(f"out must be {d_m.shape + (4,)} uint8, got {out.shape} {out.dtype}")
    valid = valid_depth_mask(d_m, codec)
    # both channels come from one quantity, the period count q = d / beta: x_B = frac(q) and
    # 255 x_R = q (255 beta / alpha). At alpha / beta = 255 the factor is exactly 1, so R and B round
    # consistently even at the ties (d / beta a half-integer) where separate float products could disagree
    # and decode a whole period off. An invalid pixel has q = 0, hence R = G = B = 0.
    q = np.multiply(d_m, CM_PER_M / codec.beta_cm, out=np.zeros(d_m.shape), where=valid)
    x_b = q - np.floor(q)
    r255 = np.minimum(q * (BYTE_MAX * codec.beta_cm / codec.alpha_cm), float(BYTE_MAX))
    if codec.gamma_mode == "mishandled":
        r255 = BYTE_MAX * (r255 / BYTE_MAX) ** codec.gamma
        x_b = x_b**codec.gamma
    # round half up, as the shader's floor(x + 0.5) for x >= 0
    r255 += 0.5
    x_b *= BYTE_MAX
    x_b += 0.5
    out[..., 0] = np.floor(r255, out=r255)
    out[..., 1] = out[..., 0]
    out[..., 2] = np.floor(x_b, out=x_b)
    out[..., 3] = valid
    out[..., 3] *= VALID_ALPHA
    return out


def decode_depth(rgba: np.ndarray, codec: Codec) -> np.ndarray:
    """Eq 3 (test oracle only): (H, W, 4) uint8 -> (H, W) float64 planar depth in m, NaN where A != 255.

    In ``mishandled`` mode the gamma is undone exactly after reading (x = (byte / 255)^(1 / gamma)) before
    Eq 3, which still leaves the whole-period errors of quantising in the gamma domain.
    """
    px = np.asarray(rgba)
    r = px[..., 0].astype(np.float64) / BYTE_MAX
    b = px[..., 2].astype(np.float64) / BYTE_MAX
    if codec.gamma_mode == "mishandled":
        r = r ** (1.0 / codec.gamma)
        b = b ** (1.0 / codec.gamma)
    ratio = codec.alpha_cm / codec.beta_cm
    d_cm = (np.round(r * ratio - b) + b) * codec.beta_cm
    return np.where(px[..., 3] == VALID_ALPHA, d_cm / CM_PER_M, np.nan)
