"""The numpy reference encoder (Eqs 1-2) against closed forms, the codec bound and the gamma study."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cosim.scenario.config.sensing import Codec
from renderer_proc.codec import decode_depth, encode_depth, valid_depth_mask

CODEC = Codec()


def test_bytes_match_closed_form():
    d_m = np.array([[1.234, 7.89], [12.5, 49.99]])
    img = encode_depth(d_m, CODEC)
    d_cm = d_m * 100.0
    assert img.dtype == np.uint8 and img.shape == (2, 2, 4)
    np.testing.assert_array_equal(img[..., 0], np.floor(255.0 * d_cm / 5000.0 + 0.5))
    np.testing.assert_array_equal(img[..., 1], img[..., 0])
    np.testing.assert_array_equal(img[..., 2], np.floor(255.0 * (d_cm % 100.0) / 100.0 + 0.5))
    assert np.all(img[..., 3] == 255)
    # 1.234 m = 123.4 cm: R = round(255 * 0.02468) = 6, B = round(255 * 0.234) = 60
    assert tuple(img[0, 0]) == (6, 6, 60, 255)


@settings(max_examples=300, deadline=None)
@given(st.floats(min_value=0.0, max_value=0.9999999, exclude_min=True),
       st.sampled_from([(5000.0, 100.0), (5000.0, 20.0), (2540.0, 10.0), (1000.0, 50.0)]))
def test_codec_bound_over_whole_range(frac, ab):
    codec = Codec(alpha_cm=ab[0], beta_cm=ab[1])
    d = np.array([[frac * codec.max_depth_m]])
    back = decode_depth(encode_depth(d, codec), codec)
    assert abs(back[0, 0] - d[0, 0]) <= codec.bound_m + 1e-12


@pytest.mark.parametrize("alpha_cm,beta_cm", [(5000.0, 100.0), (2540.0, 10.0), (2500.0, 10.0)])
def test_codec_bound_dense_sweep(alpha_cm, beta_cm):
    codec = Codec(alpha_cm=alpha_cm, beta_cm=beta_cm)
    d = np.linspace(1e-4, codec.max_depth_m * (1 - 1e-9), 400_001)[None]
    err = np.abs(decode_depth(encode_depth(d, codec), codec) - d)
    assert err.max() <= codec.bound_m + 1e-12
    assert err.max() > 0.9 * codec.bound_m          # the bound is tight, not loose


def test_half_period_ties_at_ratio_255():
    """Regression: at alpha / beta = 255, d / beta a half-integer (17.85 m with beta = 10 cm) once rounded R
    down and B up (separate float products) and decoded a whole period (10 cm) off. The scenario refuses
    ratios above 254 (Eqs 1-3 as written break there); the encoder stays exact at 255 all the same."""
    codec = Codec.model_construct(alpha_cm=2550.0, beta_cm=10.0, gamma=2.2, gamma_mode="linear")
    d = (np.arange(1, 255) + 0.5)[None] * 0.1          # every half-integer period count, m
    err = np.abs(decode_depth(encode_depth(d, codec), codec) - d)
    assert err.max() <= codec.bound_m + 1e-12


@pytest.mark.parametrize("bad", [np.inf, np.nan, 0.0, -1.0, 50.0, 80.0])
def test_invalid_pixels_carry_no_depth(bad):
    img = encode_depth(np.array([[bad, 3.0]]), CODEC)
    assert tuple(img[0, 0]) == (0, 0, 0, 0)
    assert img[0, 1, 3] == 255
    assert np.isnan(decode_depth(img, CODEC)[0, 0])
    assert not valid_depth_mask(np.array([bad]), CODEC)[0]


def test_encodes_in_place_into_destination():
    out = np.full((3, 4, 4), 7, np.uint8)
    res = encode_depth(np.full((3, 4), 2.5), CODEC, out=out)
    assert res is out and np.shares_memory(res, out)
    assert np.all(out[..., 3] == 255)
    with pytest.raises(ValueError, match="out must be"):
        encode_depth(np.full((3, 4), 2.5), CODEC, out=np.zeros((3, 4, 3), np.uint8))


def test_mishandled_gamma_costs_whole_periods():
    """docs/CONTRACTS.md: alpha = 50 m, beta = 1 m, gamma 2.2 quantised in the gamma domain: mean about
    11 cm, worst about 3 m, even with the gamma undone exactly after reading."""
    bad = Codec(gamma_mode="mishandled")
    d = np.linspace(0.01, bad.max_depth_m - 0.01, 200_001)[None]
    err = np.abs(decode_depth(encode_depth(d, bad), bad) - d)
    assert 0.08 < err.mean() < 0.15
    assert 2.0 < err.max() < 4.0
    good = np.abs(decode_depth(encode_depth(d, CODEC), CODEC) - d)
    assert good.max() <= CODEC.bound_m + 1e-12


def test_mishandled_bytes_are_gamma_domain():
    bad = Codec(gamma_mode="mishandled")
    d_m = np.array([[12.34]])
    img = encode_depth(d_m, bad)
    x_r, x_b = 1234.0 / 5000.0, 34.0 / 100.0
    assert img[0, 0, 0] == np.floor(255 * x_r**2.2 + 0.5)
    assert img[0, 0, 2] == np.floor(255 * x_b**2.2 + 0.5)


def test_ratio_strictly_between_254_and_255_breaks_the_bound():
    """The bound needs R's error (<= 0.5 (alpha / beta) / 255 periods) plus B's (<= 0.5 / 255) below half a
    period: alpha / beta <= 254. Exactly 255 still works because then R and B round one and the same q (see
    encode_depth), but in between a whole period is lost near half-integer period counts."""
    codec = Codec.model_construct(alpha_cm=2545.0, beta_cm=10.0, gamma=2.2, gamma_mode="linear")  # bypasses the validator that refuses it
    d = np.linspace(1e-4, codec.max_depth_m * (1 - 1e-9), 400_001)[None]
    err = np.abs(decode_depth(encode_depth(d, codec), codec) - d)
    assert err.max() == pytest.approx(codec.beta_cm / 100.0, rel=0.01)


def test_codec_ratios_above_254_are_refused():
    from pydantic import ValidationError

    from cosim.scenario.config import Codec

    Codec(alpha_cm=25400.0, beta_cm=100.0)
    Codec(alpha_cm=5000.0, beta_cm=5000.0 / 254.0)
    for alpha in (25450.0, 25500.0):
        with pytest.raises(ValidationError, match="exceeds 254"):
            Codec(alpha_cm=alpha, beta_cm=100.0)


@pytest.mark.parametrize("gamma_mode", ["linear", "mishandled"])
def test_bytes_equal_the_masked_formula_bit_for_bit(gamma_mode):
    """The encoder against Eqs 1-2 written with every channel masked by validity (invalid pixels: all zero),
    byte for byte, over valid depths (ties of the rounding included) and every kind of invalid one."""
    codec = Codec(gamma_mode=gamma_mode)
    rng = np.random.default_rng(7)
    d = np.concatenate([rng.uniform(0.0, 1.2 * codec.max_depth_m, 20_000),
                        (np.arange(0, 5000) + 0.5) * codec.beta_cm / 100.0 / 255.0,        # B ties
                        [np.inf, -np.inf, np.nan, 0.0, -0.0, -1.0, codec.max_depth_m, 5e-324, 1e300]])
    valid = np.isfinite(d) & (d > 0.0) & (d * 100.0 < codec.alpha_cm)
    with np.errstate(invalid="ignore", over="ignore"):
        q = np.where(valid, d * (100.0 / codec.beta_cm), 0.0)
    x_b = q - np.floor(q)
    r255 = np.minimum(q * (255.0 * codec.beta_cm / codec.alpha_cm), 255.0)
    if gamma_mode == "mishandled":
        r255, x_b = 255.0 * (r255 / 255.0) ** codec.gamma, x_b**codec.gamma
    r = np.where(valid, np.floor(r255 + 0.5), 0).astype(np.uint8)
    b = np.where(valid, np.floor(x_b * 255.0 + 0.5), 0).astype(np.uint8)
    want = np.stack([r, r, b, np.where(valid, 255, 0).astype(np.uint8)], axis=-1)
    np.testing.assert_array_equal(encode_depth(d[None], codec)[0], want)
    np.testing.assert_array_equal(valid_depth_mask(d, codec), valid)
