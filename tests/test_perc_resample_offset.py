"""Offset-LiDAR resampling (perception_proc.lidar.resample_offset) against exact ray casts of analytic scenes.

Truth is always ``cosim.testing.synthetic.raycast`` from the LiDAR origin along the same beams; the camera
images are rendered from the offset camera centres and encoded with the linear codec (Eqs 1-2).
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from cosim.scenario.config import Codec, Pattern
from cosim.testing.synthetic import Box, Plane, encode_linear, raycast, render_depth, stitched_rig
from cosim.world.camera import beam_directions
from cosim.world.patterns import beam_table, pattern_shape
from perception_proc.lidar import resample_offset as ro
from perception_proc.lidar.resample import beam_pixels, build_table, resample

CODEC = Codec()
BOUND = CODEC.bound_m
ORIGIN = np.zeros(3)


def _images(shapes, rig):
    return [encode_linear(render_depth(shapes, np.eye(4), c), CODEC) for c in rig.cameras]


def _grid(el, az, ne, na):
    p = Pattern(preset="grid", elevation_min_deg=el[0], elevation_max_deg=el[1], azimuth_min_deg=az[0],
                azimuth_max_deg=az[1], elevation_count=ne, azimuth_count=na)
    e, a = beam_table(p)
    return p, e, a, beam_directions(e, a)


def _run(shapes, rig, p, e, a):
    table = ro.build_offset_table(rig, e, a, pattern_shape(p))
    return ro.resample_offset(_images(shapes, rig), table, CODEC), table


def test_plane_at_known_distance_matches_exact_cast():
    # a fronto-parallel wall 8 m ahead, cameras 0.2 m right, 5 cm up and 10 cm back of the LiDAR: every beam
    # returns, and the plane refinement leaves only codec quantisation (range = Z / cos, so a little above
    # the depth bound at the field edge)
    rig = stitched_rig(2, 320, 240, 60.0, offset_m=(0.2, 0.05, -0.1))
    p, e, a, d = _grid((-15, 15), (-50, 50), 31, 101)
    shapes = [Plane((0.0, 0.0, 1.0), 8.0)]
    rng, _ = _run(shapes, rig, p, e, a)
    exact = raycast(shapes, ORIGIN, d)
    assert np.all(np.isfinite(exact)) and np.all(np.isfinite(rng))
    err = np.abs(rng - exact)
    assert np.median(err) <= BOUND
    assert np.max(err) <= 3 * BOUND


def test_box_edge_has_no_mixed_depths():
    # a box 5-6 m ahead of a wall at 10 m: beams at the box silhouette either return the box or the wall
    # (within 5 cm), never a depth in between; away from the edge the error is the codec's
    rig = stitched_rig(2, 320, 240, 60.0, offset_m=(0.2, 0.05, -0.1))
    p, e, a, d = _grid((-15, 15), (-50, 50), 31, 101)
    shapes = [Plane((0.0, 0.0, 1.0), 10.0), Box((-1.0, -1.0, 5.0), (1.0, 1.0, 6.0))]
    rng, _ = _run(shapes, rig, p, e, a)
    exact = raycast(shapes, ORIGIN, d)
    grid = exact.reshape(31, 101)
    edge = np.zeros(grid.shape, bool)
    jump_c = np.abs(np.diff(grid, axis=1)) > 0.5
    jump_r = np.abs(np.diff(grid, axis=0)) > 0.5
    edge[:, 1:] |= jump_c
    edge[:, :-1] |= jump_c
    edge[1:] |= jump_r
    edge[:-1] |= jump_r
    edge = edge.ravel()
    assert edge.sum() >= 100
    got = np.isfinite(rng)
    assert got[~edge].all()
    assert got[edge].mean() >= 0.8                       # a few silhouette beams fall between pixels
    err = np.abs(rng - exact)
    assert np.max(err[~edge]) <= 3 * BOUND
    assert np.max(err[edge & got]) <= 0.05


def test_stitched_seam_has_no_missing_or_doubled_beams():
    # two cameras 55 deg apart (5 deg overlap): beams whose hit both cameras see get one return each, as
    # accurate as beams seen by one camera; no beam is lost at the seam
    rig = stitched_rig(2, 320, 240, 60.0, offset_m=(0.2, 0.0, 0.0))
    p, e, a, d = _grid((-15, 15), (-50, 50), 31, 201)
    shapes = [Plane((0.0, 0.0, 1.0), 6.0)]
    rng, table = _run(shapes, rig, p, e, a)
    exact = raycast(shapes, ORIGIN, d)
    hit = d * exact[:, None]
    seen = []
    for cam in rig.cameras:
        m = cam.sensor_from_camera
        u, v = beam_pixels((hit - m[:3, 3]) @ m[:3, :3], cam.intrinsics.width, cam.intrinsics.height,
                           cam.intrinsics.f)
        seen.append((u >= 1) & (u < cam.intrinsics.width - 1) & (v >= 1) & (v < cam.intrinsics.height - 1))
    both, one = seen[0] & seen[1], seen[0] ^ seen[1]
    assert both.sum() >= 4 * 31 and (both | one).all()
    # both cameras really offer candidates for the overlap beams: the per-beam minimum must merge them
    lut = ro._finite_lut(CODEC)
    imgs = _images(shapes, rig)
    found = [set(ro._candidates(table, c, ro.words_of(i), lut)[1].tolist()) for c, i in zip(table.cameras, imgs)]
    assert len(found[0] & found[1]) >= 0.9 * both.sum()
    assert np.isfinite(rng).all()
    err = np.abs(rng - exact)
    assert np.max(err[both]) <= max(3 * BOUND, 1.5 * np.max(err[one]))
    assert np.max(err) <= 3 * BOUND


def test_near_object_occludes_far_one():
    # a small box 3 m ahead of a wall at 10 m, camera 0.3 m to the side: the camera sees wall pixels that lie
    # behind the box from the LiDAR, and those map onto the box's beams. The nearest return must win.
    rig = stitched_rig(1, 320, 240, 60.0, offset_m=(0.3, 0.0, 0.0))
    p, e, a, d = _grid((-10, 10), (-20, 20), 41, 81)
    shapes = [Plane((0.0, 0.0, 1.0), 10.0), Box((-0.3, -0.3, 3.0), (0.3, 0.3, 3.2))]
    rng, table = _run(shapes, rig, p, e, a)
    exact = raycast(shapes, ORIGIN, d)
    box = raycast(shapes[1:], ORIGIN, d)
    on_box = np.flatnonzero(np.isfinite(box) & (np.abs(exact - box) < 1e-9))
    assert on_box.size >= 300
    idx, beam, r = ro._candidates(table, table.cameras[0], ro.words_of(_images(shapes, rig)[0]),
                                  ro._finite_lut(CODEC))
    shadowed = np.intersect1d(beam[r > 5.0], on_box)          # box beams that also got a wall candidate
    assert shadowed.size >= 50
    np.testing.assert_allclose(rng[on_box], exact[on_box], atol=2 * BOUND)


def test_nearest_per_beam_is_exact_minimum():
    gen = np.random.default_rng(7)
    beam = gen.integers(0, 50, 2000)
    rng = gen.random(2000).astype(np.float32)
    win = ro._nearest_per_beam(60, beam, rng)
    for b in range(60):
        mine = np.flatnonzero(beam == b)
        if mine.size == 0:
            assert win[b] == -1
        else:
            assert rng[win[b]] == rng[mine].min() and beam[win[b]] == b


@pytest.mark.parametrize("pitch_deg", [-10.0, 15.0])
def test_zero_offset_equals_colocated_path(pitch_deg):
    # with the cameras at the LiDAR origin the general method must give the co-located answer: same beams,
    # same ranges within the codec bound (both are exact on planes up to quantisation)
    rig = stitched_rig(2, 320, 240, 60.0, pitch_deg=pitch_deg)
    p, e, a, d = _grid((-25, 25), (-50, 50), 41, 101)
    shapes = [Plane((0.0, 1.0, 0.0), -2.5)] if pitch_deg < 0 else [Plane((0.0, 0.0, 1.0), 12.0)]
    imgs = _images(shapes, rig)
    table = ro.build_offset_table(rig, e, a, pattern_shape(p))
    rng = ro.resample_offset(imgs, table, CODEC)
    co = resample(imgs, build_table(rig, d), CODEC, "planar")
    exact = raycast(shapes, ORIGIN, d)
    near = exact < 0.6 * CODEC.max_depth_m                    # away from the codec's far limit
    assert np.count_nonzero(near) >= 1000
    ok = near & np.isfinite(co)
    assert np.isfinite(rng[ok]).all()                         # no beam lost
    extra = near & np.isfinite(rng) & ~np.isfinite(co)        # beams < 0.75 px outside every image
    assert extra.sum() <= 0.002 * near.sum()
    # both are exact on a plane up to quantisation (the co-located one interpolates four pixels, the general
    # one intersects the plane of three), which grows with range / depth and the incidence angle
    scale = np.maximum(exact / 10.0, 1.0)
    diff = np.abs(rng[ok] - co[ok]) / scale[ok]
    assert np.median(diff) <= 0.5 * BOUND
    assert np.max(diff) <= 6 * BOUND
    assert np.max(np.abs(rng[ok] - exact[ok]) / scale[ok]) <= 4 * BOUND
    assert np.max(np.abs(rng[extra] - exact[extra]) / scale[extra], initial=0.0) <= 4 * BOUND


@pytest.mark.parametrize("offset_m", [(0.2, 0.0, 0.0), (0.15, 0.04, -0.1)])
def test_row_band_drops_only_pixels_that_cannot_meet_a_beam(monkeypatch, offset_m):
    # sparse rows (3 deg apart, about 15 pixels): the build keeps only pixels whose direction can come within
    # the tolerance of a row for some depth >= NEAR_RANGE_M. The answer must equal that of a table that keeps
    # every window pixel, on walls from the near limit outwards and on a floor with a box.
    rig = stitched_rig(2, 320, 240, 60.0, offset_m=offset_m)
    p, e, a, d = _grid((-15, 15), (-50, 50), 11, 101)
    table = ro.build_offset_table(rig, e, a, pattern_shape(p))
    with monkeypatch.context() as m:
        m.setattr(ro, "_row_band", lambda a_s, *args: np.ones(a_s.shape[0], bool))
        full = ro.build_offset_table(rig, e, a, pattern_shape(p))
    kept, every = (sum(c.pixel.size for c in t.cameras) for t in (table, full))
    assert kept < 0.8 * every
    # the nearest wall: every pixel's camera depth just above NEAR_RANGE_M (yaw 27.5 deg, field +-30 deg)
    scenes = [[Plane((0.0, 0.0, 1.0), z)] for z in (1.2 * ro.NEAR_RANGE_M, 1.5, 3.0, 20.0)]
    scenes.append([Plane((0.0, 1.0, 0.0), -1.5), Box((-1.0, -1.5, 3.0), (0.5, 0.5, 4.0))])
    for shapes in scenes:
        imgs = _images(shapes, rig)
        got, want = ro.resample_offset(imgs, table, CODEC), ro.resample_offset(imgs, full, CODEC)
        assert np.count_nonzero(np.isfinite(want)) >= 0.5 * d.shape[0]
        np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("hfov_deg, el_max", [(60.0, 15.0), (70.0, 40.0)])
def test_column_pretest_loses_no_point_within_the_tolerance(hfov_deg, el_max):
    # the per-pixel column bound is a pre-test: widened to half a column it may add only points that the
    # float32 cosine test lets through beyond the tolerance (its rounding), never one within it
    rig = stitched_rig(2, 320, 240, hfov_deg, yaw_step_deg=hfov_deg - 10.0, pitch_deg=-5.0,
                       offset_m=(0.2, 0.0, 0.0))
    p, e, a, d = _grid((-el_max, el_max), (-55, 55), 81, 121)
    table = ro.build_offset_table(rig, e, a, pattern_shape(p))
    shapes = [Plane((0.0, 1.0, 0.0), -1.5), Box((-1.5, -1.5, 3.0), (0.5, 1.0, 4.0)), Plane((0.0, 0.0, 1.0), 9.0)]
    lut = ro._finite_lut(CODEC)
    total = 0
    for cam, img in zip(table.cameras, _images(shapes, rig)):
        assert np.all(cam.tol_col < 0.49)
        wide = dataclasses.replace(cam, tol_col=np.full(cam.pixel.size, 0.49, np.float32))
        got = ro._candidates(table, cam, ro.words_of(img), lut)
        want = ro._candidates(table, wide, ro.words_of(img), lut)
        assert np.isin(got[0], want[0]).all()
        extra = ~np.isin(want[0], got[0])
        i, beam = want[0][extra], want[1][extra]
        z = np.take(lut, ro.lut_key(ro.words_of(img)[cam.pixel[i]])).astype(np.float64)
        pts = np.stack([cam.kx[i] * z, cam.ky[i] * z, z], axis=1) @ cam.rotation.T + cam.translation
        cosang = np.einsum("ij,ij->i", pts, table.directions[beam]) / np.linalg.norm(pts, axis=1)
        assert np.all(np.arccos(np.minimum(cosang, 1.0)) > table.tol)
        assert extra.sum() <= 0.02 * want[0].size
        total += got[0].size
    assert total >= 0.5 * d.shape[0]


def test_wrong_image_count_is_refused():
    rig = stitched_rig(2, 64, 48, 60.0, offset_m=(0.2, 0.0, 0.0))
    p, e, a, _ = _grid((-5, 5), (-20, 20), 5, 9)
    table = ro.build_offset_table(rig, e, a, pattern_shape(p))
    with pytest.raises(ValueError, match="expected 2 images"):
        ro.resample_offset(_images([Plane((0.0, 0.0, 1.0), 5.0)], rig)[:1], table, CODEC)
