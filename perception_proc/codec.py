"""Depth decoder of the paper's Eq 3 (DESIGN.md section 4), written independently of the renderer's encoder.

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

from cosim.config import Codec

__all__ = ["decode_depth", "decode_bytes", "decode_lut", "decode_words", "decode_words_linear", "lut_key", "CM_PER_M",
           "R_SATURATED"]

#: centimetres per metre (the codec works in cm, everything else in m)
CM_PER_M = 100.0
#: red byte value that marks a saturated (out-of-range) depth
R_SATURATED = 255
_INV255 = np.float32(1.0 / 255.0)
#: the low bit of A in a little-endian RGBA word
_VALID_BIT = 1 << 24
#: 2^23 as float32 and its bit pattern (decode_words_linear)
_TWO23 = np.float32(1 << 23)
_TWO23_BITS = np.uint32(0x4B000000)


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
    """Decode gathered RGBA words (any shape, uint32) with a :func:`decode_lut` table: depth m float32, NaN."""
    return np.take(lut, lut_key(words))


def decode_words_linear(words: np.ndarray, codec: Codec) -> np.ndarray:
    """Eq 3 computed on RGBA words (any shape, uint32, little-endian R G B A) of a ``linear`` codec: depth m
    float32, NaN where invalid (A's low bit clear, or R saturated), the same bytes as the
    :func:`decode_lut` entry.

    The same float32 operations as :func:`decode_bytes` in the same order (byte / 255 as ``byte *
    float32(1/255)``, rint, no fused multiply-add), so the same numbers as the table, which is built by
    them; but as a dozen vectorised passes instead of one gather per word, several times fewer instructions
    for the thousands of words a frame decodes."""
    if codec.gamma_mode != "linear":
        raise ValueError(f"decode_words_linear needs a linear codec, got gamma_mode={codec.gamma_mode!r}")
    w = np.asarray(words, dtype=np.uint32)
    # a byte k as float32 without a conversion loop: the float32 with bits 0x4B000000 | k is 2^23 + k
    # exactly, so subtracting 2^23 leaves k exactly (bit operations and one subtraction, all vectorised)
    r = w & np.uint32(0xFF)
    r |= _TWO23_BITS
    xr = r.view(np.float32)
    xr -= _TWO23
    xr *= _INV255
    b = np.right_shift(w, np.uint32(16))
    b &= np.uint32(0xFF)
    b |= _TWO23_BITS
    xb = b.view(np.float32)
    xb -= _TWO23
    xb *= _INV255
    depth = xr
    depth *= np.float32(codec.alpha_cm / codec.beta_cm)
    depth -= xb
    np.rint(depth, out=depth)
    depth += xb
    depth *= np.float32(codec.beta_cm / CM_PER_M)
    # A's low bit (valid) and R: invalid below the bit, or with the bit and R = 255
    key = np.bitwise_and(w, np.uint32(_VALID_BIT | R_SATURATED), out=b)   # xb's storage: xb is done
    invalid = key < np.uint32(_VALID_BIT)
    invalid |= key == np.uint32(_VALID_BIT | R_SATURATED)
    np.copyto(depth, np.float32(np.nan), where=invalid)
    return depth


def decode_depth(rgba: np.ndarray, codec: Codec) -> np.ndarray:
    """Decode a depth-encoded image.

    ``rgba``: (H, W, 4) uint8, row 0 at the top, linear bytes (Eqs 1-2). Returns (H, W) float32 planar depth
    Z in m along the camera's optical axis (camera frame), NaN where the pixel is invalid.
    """
    img = np.asarray(rgba)
    if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] != 4:
        raise ValueError(f"expected an (H, W, 4) uint8 image, got {img.shape} {img.dtype}")
    return decode_bytes(img[..., 0], img[..., 2], img[..., 3], codec)
