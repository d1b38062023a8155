"""Depth codec (Eqs 1-3): the decoder against a reference encoder written here from docs/CONTRACTS.md."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cosim.scenario.config import Codec
from cosim.testing.synthetic import encode_linear
from perception_proc.lidar.codec import decode_bytes, decode_depth, decode_lut, decode_words, lut_key


def encode_reference(d_m: np.ndarray, alpha_cm: float, beta_cm: float, gamma: float = 2.2,
                     mishandled: bool = False) -> np.ndarray:
    """docs/CONTRACTS.md, written independently: x_R = min(d/alpha, 1), x_B = (d mod beta)/beta (d in cm);
    linear bytes R = G = round(255 x_R), B = round(255 x_B); mishandled stores x^gamma. A = 255 when d < alpha."""
    d = np.atleast_1d(np.asarray(d_m, dtype=np.float64)) * 100.0
    xr = np.minimum(d / alpha_cm, 1.0)
    xb = np.mod(d, beta_cm) / beta_cm
    if mishandled:
        xr, xb = xr**gamma, xb**gamma
    r = np.rint(255 * xr).astype(np.uint8)
    img = np.stack([r, r, np.rint(255 * xb).astype(np.uint8), np.where(d < alpha_cm, 255, 0).astype(np.uint8)], -1)
    return img.reshape(1, -1, 4)


def _roundtrip(d_m, codec: Codec, mishandled=False):
    img = encode_reference(d_m, codec.alpha_cm, codec.beta_cm, codec.gamma, mishandled)
    return decode_depth(img, codec)[0].astype(np.float64)


@settings(max_examples=300, deadline=None)
@given(
    alpha=st.floats(200.0, 10_000.0),
    ratio=st.one_of(st.floats(1.5, 254.0), st.just(254.0)),
    frac=st.lists(st.floats(0.0, 1.0, exclude_max=True), min_size=1, max_size=64),
)
def test_bound_holds_over_the_whole_range(alpha, ratio, frac):
    codec = Codec(alpha_cm=alpha, beta_cm=alpha / ratio)
    d = np.asarray(frac) * alpha / 100.0
    got = _roundtrip(d, codec)
    r_byte = np.rint(255 * np.minimum(d * 100 / alpha, 1.0))
    valid = r_byte < 255
    assert np.all(np.isnan(got[~valid]))
    # float32 decode adds a few ulps of the depth on top of beta/510
    tol = codec.bound_m + 4e-7 * np.maximum(d, 1.0)
    assert np.all(np.abs(got[valid] - d[valid]) <= tol[valid])


def test_dense_sweep_default_codec_bound_is_tight():
    codec = Codec()
    d = np.linspace(0.0, 49.8, 500_001)
    err = np.abs(_roundtrip(d, codec) - d)
    assert np.nanmax(err) <= codec.bound_m + 2e-5
    assert np.nanmax(err) >= 0.9 * codec.bound_m          # the bound is attained: the test can see a regression
    assert np.count_nonzero(np.isnan(err)) == 0


def test_ratio_256_breaks_the_period_count():
    # Codec refuses it; the decoder maths itself then makes whole-period errors (docs/CONTRACTS.md)
    with pytest.raises(ValueError, match="exceeds 254"):
        Codec(alpha_cm=25_600.0, beta_cm=100.0)
    alpha, beta = 25_600.0, 100.0
    d = np.linspace(0.0, 250.0, 200_001)
    img = encode_reference(d, alpha, beta)
    r, b = img[0, :, 0] / 255.0, img[0, :, 2] / 255.0
    dd = (np.rint(r * alpha / beta - b) + b) * beta / 100.0
    assert np.max(np.abs(dd - d)) >= 0.5 * beta / 100.0


def test_saturated_and_background_are_invalid():
    codec = Codec(alpha_cm=5000.0, beta_cm=100.0)
    got = _roundtrip(np.array([49.0, 50.0, 60.0]), codec)
    assert np.isfinite(got[0]) and np.isnan(got[1]) and np.isnan(got[2])
    img = encode_reference(np.array([10.0]), 5000.0, 100.0)
    img[..., 3] = 0
    assert np.isnan(decode_depth(img, codec)[0, 0])


def test_mishandled_gamma_is_visibly_worse():
    lin = Codec(alpha_cm=5000.0, beta_cm=100.0)
    bad = Codec(alpha_cm=5000.0, beta_cm=100.0, gamma_mode="mishandled")
    d = np.random.default_rng(1).uniform(0.0, 49.0, 200_000)
    e_lin = np.abs(_roundtrip(d, lin) - d)
    e_bad = np.abs(_roundtrip(d, bad, mishandled=True) - d)
    assert np.nanmax(e_lin) <= lin.bound_m + 2e-5
    # docs/CONTRACTS.md: mean about 11 cm, worst about 3 m at alpha 50 m, beta 1 m
    assert 0.05 <= np.nanmean(e_bad) <= 0.25
    assert 1.0 <= np.nanmax(e_bad) <= 5.0


def test_synthetic_encoder_matches_reference():
    codec = Codec()
    d = np.random.default_rng(2).uniform(0.0, 55.0, (7, 11))
    d[0, 0] = np.nan
    ref = encode_reference(np.nan_to_num(d, nan=1e9), codec.alpha_cm, codec.beta_cm).reshape(7, 11, 4)
    ours = encode_linear(d, codec)
    np.testing.assert_array_equal(ours[..., 3], np.where(np.isfinite(d) & (d < 50.0), 255, 0))
    hit = ours[..., 3] == 255
    assert hit.sum() > 50
    np.testing.assert_array_equal(ours[hit], ref[hit])


def test_decode_rejects_bad_shape():
    with pytest.raises(ValueError, match=r"\(H, W, 4\) uint8"):
        decode_depth(np.zeros((4, 4, 3), np.uint8), Codec())


@pytest.mark.parametrize("gamma_mode", ["linear", "mishandled"])
def test_table_decode_equals_the_per_channel_decode_for_every_word(gamma_mode):
    """The decode table (``decode_lut`` indexed by ``lut_key`` of the RGBA word) against Eq 3 on the channels
    (``decode_bytes``), bit for bit, over every (R, B) pair with G arbitrary and A = 0 or 255."""
    codec = Codec(gamma_mode=gamma_mode)
    r, b = (c.astype(np.uint8).ravel() for c in np.meshgrid(np.arange(256), np.arange(256), indexing="ij"))
    g = np.random.default_rng(3).integers(0, 256, r.size).astype(np.uint8)   # the key must ignore G
    lut = decode_lut(codec)
    for a_val in (0, 255):
        a = np.full(r.size, a_val, np.uint8)
        words = np.stack([r, g, b, a], axis=1).copy().view("<u4").ravel()
        got = decode_words(words, lut)
        want = decode_bytes(r, b, a, codec)
        np.testing.assert_array_equal(got, want)
        assert np.isnan(got).all() if a_val == 0 else np.isnan(got).sum() == 256   # R = 255 saturates
    assert lut_key(np.array([0xFF_AB_CD_EF], np.uint32))[0] == (0xEF | 0xAB << 8 | 1 << 16)
