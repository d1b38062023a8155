"""The depth camera's noise kernel (perception_proc.cameras.tof) against its readable reference
(perception_proc.cameras.tof_reference): the same numbers to the bit on depth images with edges, misses, grazing
surfaces and borders, with and without noise."""
from __future__ import annotations

import numpy as np
import pytest

from cosim.scenario.config.cameras import DepthCamera
from cosim.world.camera import Pinhole
from perception_proc.cameras import tof, tof_reference

PIN = Pinhole(width=96, height=72, hfov_rad=1.1)


def _depth(seed: int) -> np.ndarray:
    """A planar depth image (72, 96) float32 m: a tilted floor (grazing towards the top), a box in front of it
    (depth edges), a strip of sky (NaN) and single missing pixels."""
    rng = np.random.default_rng(seed)
    h, w = PIN.height, PIN.width
    v = np.arange(h)[:, None] + 0.5
    z = 3.0 + 40.0 / np.maximum(v, 4.0) + 0.002 * rng.standard_normal((h, w))
    z[20:40, 30:60] = 2.5 + 0.01 * np.arange(30)[None, :]
    z[:6] = np.nan
    z[rng.integers(0, h, 15), rng.integers(0, w, 15)] = np.nan
    return z.astype(np.float32)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_incidence_and_flying_mask_equal_the_reference_to_the_bit(seed):
    z = np.asarray(_depth(seed), np.float64)
    a, b = tof.incidence(PIN, z), tof_reference.incidence(PIN, z)
    assert np.isfinite(a).mean() > 0.8 and np.nanmax(a) > np.radians(60.0)      # grazing pixels are present
    assert a.tobytes() == b.tobytes()
    for x, y in zip(tof.flying_mask(z, 0.05), tof_reference.flying_mask(z, 0.05)):
        assert x.tobytes() == y.tobytes()
    assert tof.flying_mask(z, 0.05)[0].any()


@pytest.mark.parametrize("noise", [True, False])
def test_tof_depth_equals_the_reference_to_the_bit(noise):
    cam = DepthCamera(kind="depth_camera", noise=noise, range_max_m=8.0,
                      mount={"parent": "world"})
    z = _depth(7)
    a = tof.tof_depth(z, PIN, cam, tof.frame_generator(3, 11, 0))
    b = tof_reference.tof_depth(z, PIN, cam, tof.frame_generator(3, 11, 0))
    assert a.dtype == np.float32 and a.tobytes() == b.tobytes()
    if noise:
        assert not np.array_equal(a, tof.tof_depth(z, PIN, cam, None), equal_nan=True)   # the noise is drawn
