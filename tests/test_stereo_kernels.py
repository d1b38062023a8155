"""The stereo camera's per-pixel kernels against their readable forms, bit for bit (perception_proc.cameras.stereo,
perception_proc.cameras.subpixel): the grey conversion straight from RGBA, the matcher output's validity mask,
and the sub-pixel refinement with its grid made once."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from perception_proc.cameras.stereo import FIXED_POINT, disparity, grey
from perception_proc.cameras.subpixel import refine_disparity, refine_disparity_reference

H, W = 120, 160


def _texture(seed: int) -> np.ndarray:
    """(H, W) float32 smooth random texture, 0-255."""
    noise = np.random.default_rng(seed).uniform(0.0, 255.0, (H, W)).astype(np.float32)
    return cv2.GaussianBlur(noise, (0, 0), 1.5)


def test_grey_of_rgba_is_the_luma_of_its_rgb_bytes():
    rgba = np.random.default_rng(1).integers(0, 256, (H, W, 4), dtype=np.uint8)
    reference = cv2.cvtColor(np.ascontiguousarray(rgba[..., :3]), cv2.COLOR_RGB2GRAY)
    np.testing.assert_array_equal(grey(rgba), reference)
    np.testing.assert_array_equal(grey(rgba[..., :3]), reference)          # RGB, not contiguous
    other = rgba.copy()
    other[..., 3] = 255 - other[..., 3]
    np.testing.assert_array_equal(grey(other), reference)                  # alpha plays no part
    assert not np.array_equal(grey(rgba[..., ::-1]), reference)           # BGR order is another image


class _FixedMatcher:
    """A matcher whose output is ``raw`` (fixed-point int16)."""

    def __init__(self, raw: np.ndarray):
        self.raw = raw

    def compute(self, left, right):
        return self.raw


@pytest.mark.parametrize("min_disparity_px", [-3, 0, 1, 14])
def test_disparity_is_invalid_below_the_search_and_at_zero(min_disparity_px):
    raw = np.arange(-40, 1600, 7, dtype=np.int16).reshape(1, -1)
    d = disparity(_FixedMatcher(raw), None, None, min_disparity_px)
    invalid = (raw <= (min_disparity_px - 1) * FIXED_POINT) | (raw <= 0)
    assert d.dtype == np.float32
    np.testing.assert_array_equal(np.isnan(d), invalid)
    np.testing.assert_array_equal(d[~invalid], raw[~invalid] / np.float32(FIXED_POINT))


def _pair() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Grey pair (uint8) whose right image is the left shifted by a smooth 8-12 px disparity, a flat band (no
    texture) and the matcher's whole-pixel disparity (float32, NaN in a corner)."""
    left = _texture(2)
    left[:, 60:75] = 128.0                                                   # no gradient: flat windows
    truth = (8.0 + 4.0 * np.sin(np.linspace(0.0, 3.0, W)))[None, :].repeat(H, 0).astype(np.float32)
    cols = np.arange(W, dtype=np.float32)[None, :] + truth
    rows = np.arange(H, dtype=np.float32)[:, None].repeat(W, 1)
    right = cv2.remap(left, cols.astype(np.float32), rows, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    d = np.round(truth)
    d[:10, :10] = np.nan
    return left.astype(np.uint8), np.clip(right, 0, 255).astype(np.uint8), d


@pytest.mark.parametrize(("window_px", "iterations", "max_step_px"), [(5, 2, 1.0), (3, 1, 0.5), (7, 3, 1.0)])
def test_refine_disparity_gives_the_bits_of_its_reference(window_px, iterations, max_step_px):
    left, right, d = _pair()
    got = refine_disparity(left, right, d, window_px, iterations, max_step_px)
    ref = refine_disparity_reference(left, right, d, window_px, iterations, max_step_px)
    assert got.dtype == ref.dtype == np.float32
    np.testing.assert_array_equal(got.view(np.uint32), ref.view(np.uint32))
    valid = np.isfinite(ref)
    assert 0.3 < valid.mean() < 0.99                                         # some refined, some invalid
    assert np.count_nonzero(ref[valid] != d[valid]) > valid.sum() // 2      # the step moved them


def test_refine_disparity_leaves_its_inputs_and_grid_unchanged():
    left, right, d = _pair()
    before = d.copy()
    first = refine_disparity(left, right, d)
    np.testing.assert_array_equal(d, before)
    np.testing.assert_array_equal(refine_disparity(left, right, d).view(np.uint32), first.view(np.uint32))
