"""Depth decoder of the paper's Eq 3 (docs/CONTRACTS.md), written independently of the renderer's encoder.

Stored bytes are linear (``gamma_mode == "linear"``): R = G = round(255 min(d/alpha, 1)),
B = round(255 (d mod beta)/beta), d in cm. Eq 3: d' = [round(R/255 alpha/beta - B/255) + B/255] beta.
With ``gamma_mode == "mishandled"`` the shader's x^gamma was stored without being undone; the decoder undoes
it exactly (x = (byte/255)^(1/gamma)) before Eq 3, which still leaves whole-period errors (the error study).

Invalid pixels decode to NaN: alpha byte 0 (no hit or out of range) and R = 255 (saturated: d >= alpha, or
within half an R step of it, where a wrong period count would follow).
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from cosim.scenario.config import Codec

__all__ = ["decode_depth", "decode_bytes", "decode_lut", "decode_words", "lut_key", "CM_PER_M", "R_SATURATED"]

#: centimetres per metre (the codec works in cm, everything else in m)
CM_PER_M = 100.0
#: red byte value that marks a saturated (out-of-range) depth
R_SATURATED = 255
_INV255 = np.float32(1.0 / 255.0)


def _linear(byte: np.ndarray, codec: Codec) -> np.ndarray:
    """Byte values (any shape, uint8) -> the linear fraction x in [0, 1], float32."""
    x = byte.astype(np.float32) * _INV255
    if codec.gamma_mode == "mishandled":
        x = np.power(x, np.float32(1.0 / codec.gamma))
    return x


def decode_bytes(r: np.ndarray, b: np.ndarray, a: np.ndarray, codec: Codec) -> np.ndarray:
    """Eq 3 on separate channel arrays (same shape, uint8) -> planar depth, m, float32, NaN where invalid.

    The green channel duplicates red and is not needed. This is the per-beam form used after a gather.
    """
    ratio = np.float32(codec.alpha_cm / codec.beta_cm)
    xr = _linear(r, codec)
    xb = _linear(b, codec)
    periods = np.rint(xr * ratio - xb)
    depth = (periods + xb) * np.float32(codec.beta_cm / CM_PER_M)
    invalid = (a == 0) | (r == R_SATURATED)
    depth[invalid] = np.nan
    return depth


@lru_cache(maxsize=8)
def decode_lut(codec: Codec) -> np.ndarray:
    """Eq 3 tabulated for every (R, B, valid) byte combination: (2^17,) float32 m, NaN where invalid.

    Index with :func:`lut_key` (R | B << 8 | valid << 16). Built by :func:`decode_bytes` itself, so the two
    agree bit for bit; the per-frame decode of a gathered word is then one integer key and one table read
    (512 KiB: the table stays in cache).
    """
    key = np.arange(1 << 17, dtype=np.uint32)
    r = (key & np.uint32(0xFF)).astype(np.uint8)
    b = ((key >> np.uint32(8)) & np.uint32(0xFF)).astype(np.uint8)
    a = np.where(key >> np.uint32(16), np.uint8(255), np.uint8(0))
    lut = decode_bytes(r, b, a, codec)
    lut.flags.writeable = False                         # shared by every caller through the cache
    return lut


def lut_key(words: np.ndarray) -> np.ndarray:
    """Little-endian RGBA words (any shape, uint32) -> key R | B << 8 | (A & 1) << 16 into the decode table.

    Valid pixels carry A = 255 and invalid ones A = 0 (the renderer contract), so the low bit of A decides.
    Four integer operations: (w >> 8) holds G | B << 8 | A << 16, masked to B and A's low bit.
    """
    w = np.asarray(words, dtype=np.uint32)
    key = w >> np.uint32(8)
    key &= np.uint32(0x1FF00)
    key |= w & np.uint32(0xFF)
    return key


def decode_words(words: np.ndarray, lut: np.ndarray) -> np.ndarray:
    """Decode gathered RGBA words (any shape, uint32) with a :func:`decode_lut` table: depth m float32, NaN.

    The key has 17 bits, so it always lies in the table: the gather skips numpy's per-index range check."""
    return np.take(lut, lut_key(words), mode="wrap")


def decode_depth(rgba: np.ndarray, codec: Codec) -> np.ndarray:
    """Decode a depth-encoded image.

    ``rgba``: (H, W, 4) uint8, row 0 at the top, linear bytes (Eqs 1-2). Returns (H, W) float32 planar depth
    Z in m along the camera's optical axis (camera frame), NaN where the pixel is invalid.
    """
    img = np.asarray(rgba)
    if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] != 4:
        raise ValueError(f"expected an (H, W, 4) uint8 image, got {img.shape} {img.dtype}")
    return decode_bytes(img[..., 0], img[..., 2], img[..., 3], codec)
