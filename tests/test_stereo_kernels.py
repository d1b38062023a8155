"""The stereo camera's per-pixel kernels against their readable forms, bit for bit (perception_proc.cameras.stereo,
perception_proc.cameras.subpixel): the grey conversion straight from RGBA, the matcher output's validity mask,
the sub-pixel refinement with its grid made once, the whole depth path with its invalid pixels written once, the
camera points' ranges and the accuracy's ray directions made for the sampled pixels only."""
from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from cosim.scenario.config.cameras import StereoCamera
from cosim.world.camera import Pinhole
from perception_proc.accuracy.sensors import sample_pixels
from perception_proc.cameras import stereo
from perception_proc.cameras.pipeline import ranges_of
from perception_proc.cameras.stereo import (
    FIXED_POINT,
    camera_disparity,
    disparity,
    grey,
    kept_raw_range,
    make_matcher,
    stereo_depth,
    stereo_depth_reference,
)
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


def _camera(**keys) -> StereoCamera:
    """A small stereo camera (160 x 120) searching 16 disparities from ``min_disparity_px`` (default 2)."""
    base = {"kind": "stereo_camera", "width_px": W, "height_px": H, "num_disparities": 16, "min_disparity_px": 2,
            "block_size": 5, "baseline_m": 0.2, "range_min_m": 1.0, "range_max_m": 20.0,
            "mount": {"parent": "world"}}
    return StereoCamera(**{**base, **keys})


@pytest.mark.parametrize("min_disparity_px", [0, 1, 2, 14, 40])
@pytest.mark.parametrize("edge_px", [1.0, 0.3, -1.5])
def test_kept_raw_range_keeps_what_camera_disparity_keeps(min_disparity_px, edge_px, monkeypatch):
    monkeypatch.setattr(stereo, "SEARCH_EDGE_PX", edge_px)          # -1.5: the matcher's own floor binds
    cam = _camera(min_disparity_px=min_disparity_px, texture_threshold=0.0, subpixel="matcher")
    raw = np.arange(-32768, 32768, dtype=np.int32).astype(np.int16).reshape(256, 256)   # every fixed-point value
    img = np.zeros((256, 256), np.uint8)
    kept = np.isfinite(camera_disparity(_FixedMatcher(raw), cam, img, img))
    lo, hi = kept_raw_range(cam)
    np.testing.assert_array_equal((raw >= lo) & (raw <= hi), kept)
    np.testing.assert_array_equal(cv2.inRange(raw, lo, hi) > 0, kept)
    assert 0 < kept.sum() < raw.size


def _rgba(grey_image: np.ndarray) -> np.ndarray:
    """(H, W, 4) uint8: a grey image as RGBA, the colour channels apart so that the luma is a weighted sum."""
    g = grey_image.astype(np.int16)
    return np.stack([g, np.clip(g + 9, 0, 255), np.clip(g - 7, 0, 255), np.full_like(g, 255)], -1).astype(np.uint8)


def _raw_of(d: np.ndarray, seed: int) -> np.ndarray:
    """Fixed-point int16 disparities near ``d`` px (NaN: 0), with values below, at and past the search's ends,
    zeros and negatives scattered in."""
    rng = np.random.default_rng(seed)
    raw = np.round(np.nan_to_num(d) * FIXED_POINT + rng.integers(-24, 25, d.shape)).astype(np.int16)
    odd = rng.random(d.shape)
    raw[odd < 0.05] = 0
    raw[(odd >= 0.05) & (odd < 0.08)] = -16
    raw[(odd >= 0.08) & (odd < 0.12)] = rng.integers(0, 700, int(np.count_nonzero((odd >= 0.08) & (odd < 0.12))))
    return raw


@pytest.mark.parametrize("keys", [{}, {"texture_threshold": 0.0}, {"subpixel": "matcher"},
                                  {"range_min_m": 7.5, "range_max_m": 9.0}, {"min_disparity_px": 0},
                                  {"matcher": "bm", "block_size": 7}, {"sgbm_mode": "3way", "block_size": 3}])
def test_stereo_depth_gives_the_bits_of_its_reference(keys):
    cam = _camera(**keys)
    left, right, d = _pair()
    left_rgba, right_rgba = _rgba(left), _rgba(right)
    fb = 80.0                                                   # f B, px m: 8-12 px are 6.7-10 m
    for matcher in (make_matcher(cam), _FixedMatcher(_raw_of(d, 3))):
        got = stereo_depth(matcher, cam, fb / cam.baseline_m, left_rgba, right_rgba)
        ref = stereo_depth_reference(matcher, cam, fb / cam.baseline_m, left_rgba, right_rgba)
        assert got.dtype == ref.dtype == np.float32
        np.testing.assert_array_equal(got.view(np.uint32), ref.view(np.uint32))
        assert 0.05 < np.isfinite(ref).mean() < 0.98                         # some depths, some invalid


def test_the_camera_ranges_are_numpys_norm_to_the_bit():
    rng = np.random.default_rng(5)
    points = rng.normal(0.0, 3.0, (5000, 3)) * rng.uniform(1e-3, 1e3, (5000, 1))
    points[::7] = np.nan
    np.testing.assert_array_equal(ranges_of(points).view(np.uint64), np.linalg.norm(points, axis=1).view(np.uint64))


@pytest.mark.parametrize(("width", "height", "hfov_deg"), [(1024, 544, 95.4), (160, 120, 70.0), (33, 17, 120.0)])
def test_ray_directions_at_some_pixels_are_rows_of_the_whole_grid(width, height, hfov_deg):
    pin = Pinhole(width, height, math.radians(hfov_deg))
    pixels = sample_pixels(pin, 4096, 0, 7)
    whole = pin.ray_directions().reshape(-1, 3)
    np.testing.assert_array_equal(pin.ray_directions_at(pixels).view(np.uint64), whole[pixels].view(np.uint64))
    np.testing.assert_array_equal(pin.ray_directions_at(np.arange(width * height)).view(np.uint64),
                                  whole.view(np.uint64))
