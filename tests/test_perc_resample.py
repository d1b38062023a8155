"""LiDAR resampling (Eqs 6-7 corrected) against closed forms on analytic scenes."""
from __future__ import annotations

import math

import numpy as np
import pytest

from cosim.scenario.config import Codec, Pattern
from cosim.testing.synthetic import Box, Plane, encode_linear, raycast, render_depth, stitched_rig
from cosim.world.camera import Pinhole, Rig, RigCamera, beam_directions, paper_angles
from cosim.world.patterns import beam_table, pattern_shape
from perception_proc.lidar.resample import beam_pixels, build_table, paper_pixel, resample
from perception_proc.lidar.resample_offset import build_offset_table, is_offset, resample_offset

CODEC = Codec()
BOUND = CODEC.bound_m


def _images(shapes, rig):
    return [encode_linear(render_depth(shapes, np.eye(4), c), CODEC) for c in rig.cameras]


def _grid(el=(-20.0, 20.0), az=(-45.0, 45.0), ne=41, na=91):
    p = Pattern(preset="grid", elevation_min_deg=el[0], elevation_max_deg=el[1], azimuth_min_deg=az[0],
                azimuth_max_deg=az[1], elevation_count=ne, azimuth_count=na)
    return p, *beam_table(p)


def test_corrected_eq7_matches_projection_and_printed_eq7_collapses_to_one_column():
    cam = Pinhole(640, 480, math.radians(60.0))
    e = np.radians(np.linspace(-20, 20, 9))[:, None] * np.ones((1, 11))
    a = np.radians(np.linspace(-25, 25, 11))[None, :] * np.ones((9, 1))
    th, ph = paper_angles(e, a)
    # our beam directions have azimuth to the left; the paper's phi runs from +X to +Z
    u, v = paper_pixel(th, ph, cam.width, cam.height, cam.f)
    uu, vv = beam_pixels(beam_directions(e, a), cam.width, cam.height, cam.f)
    np.testing.assert_allclose(u, uu, atol=1e-9)
    np.testing.assert_allclose(v, vv, atol=1e-9)
    r = cam.f / (np.sin(th) * np.sin(ph))
    u_printed = r * np.sin(th) * np.sin(ph) + cam.width / 2
    assert np.ptp(u_printed) < 1e-9                    # every beam in one column: why the print is wrong
    assert np.ptp(u) > 300


def test_planar_depth_to_range_costs_41_percent_at_45_deg():
    rig = Rig((RigCamera("cam0", Pinhole(801, 401, math.radians(100.0)), np.eye(4)),))
    e, a = np.zeros(3), np.radians([0.0, 30.0, 45.0])
    table = build_table(rig, beam_directions(e, a))
    imgs = _images([Plane((0.0, 0.0, 1.0), 10.0)], rig)      # fronto-parallel wall at Z = 10 m
    rng = resample(imgs, table, CODEC, "planar")
    np.testing.assert_allclose(rng, 10.0 / np.cos(a), atol=2 * BOUND)
    assert rng[2] / 10.0 == pytest.approx(1.41421, abs=1e-3)


@pytest.mark.parametrize("pitch_deg", [0.0, 25.0])
def test_ring_on_flat_floor_lies_on_the_analytic_conic(pitch_deg):
    # LiDAR 3 m above a floor, pitched down: each ring of constant elevation meets the floor on a conic; the
    # range of each beam is the closed form h / (-n . s). A polygon (wrong Eq 7, no planar-to-range step)
    # would leave errors of centimetres to metres.
    p = math.radians(pitch_deg)
    up = np.array([0.0, math.cos(p), math.sin(p)])               # floor normal in the sensor frame
    floor = Plane(tuple(up), -3.0)
    _, e, a = _grid(el=(-35.0, -5.0), az=(-50.0, 50.0), ne=31, na=201)
    d = beam_directions(e, a)
    rig = stitched_rig(2, 640, 480, 60.0, pitch_deg=-20.0)
    imgs = _images([floor], rig)
    table = build_table(rig, d)
    expect = 3.0 / -(d @ up)
    hits = (expect > 0) & (expect < 40.0)
    ok = table.covered & hits
    assert ok.sum() > 0.9 * hits.sum() > 1000
    for sampler, tol in (("planar", 2.5 * BOUND * expect[ok].max() / 3.0), ("nearest", None)):
        rng = resample(imgs, table, CODEC, sampler)
        err = np.abs(rng[ok] - expect[ok])
        if tol is not None:
            assert np.nanmax(err) <= tol
            ring = np.isclose(e, np.radians(-30.0)) & ok
            assert ring.sum() > 100
            pts = d[ring] * rng[ring, None]
            assert np.max(np.abs(pts @ up + 3.0)) <= 3 * BOUND            # on the floor plane
            assert np.max(np.abs(pts @ (d[ring][0] * 0 + np.array([0, 1, 0])) / rng[ring]
                                 - np.sin(np.radians(-30.0)))) < 1e-9   # and on the cone of the ring
        else:
            assert np.nanmean(err) > 3 * BOUND                             # nearest pixel is measurably worse


@pytest.mark.parametrize("incidence_deg", [0.0, 60.0, 80.0])
def test_shallow_incidence_against_closed_form(incidence_deg):
    # A plane whose normal makes ``incidence`` with the optical axis. Nearest pixel: the range is exactly the
    # one through the pixel centre scaled onto the beam, Z_pix / s_z; planar sampler: the exact range.
    cam = Pinhole(640, 480, math.radians(60.0))
    rig = Rig((RigCamera("cam0", cam, np.eye(4)),))
    i = math.radians(incidence_deg)
    n = np.array([math.sin(i), 0.0, -math.cos(i)])
    plane = Plane(tuple(n), -8.0)                                   # n . p = -8: 8 m along the axis
    _, e, a = _grid(el=(-10, 10), az=(-12, 12), ne=21, na=49)
    d = beam_directions(e, a)
    table = build_table(rig, d)
    imgs = _images([plane], rig)
    exact = raycast([plane], np.zeros(3), d)
    ct = table.cameras[0]
    col, row = ct.pixel % cam.width, ct.pixel // cam.width
    ray = np.stack([col + 0.5 - cam.width / 2, cam.height / 2 - (row + 0.5), np.full(col.shape, cam.f)], 1)
    ray /= np.linalg.norm(ray, axis=1, keepdims=True)
    z_pix = raycast([plane], np.zeros(3), ray) * ray[:, 2]
    near_closed = z_pix / d[ct.beams, 2]
    near = resample(imgs, table, CODEC, "nearest")
    tol = 2 * BOUND / d[:, 2].min()
    inr = near_closed < 0.95 * CODEC.max_depth_m
    assert inr.sum() > 0.5 * inr.size
    np.testing.assert_allclose(near[ct.beams][inr], near_closed[inr], atol=tol)
    assert np.isnan(near[ct.beams][near_closed > CODEC.max_depth_m / d[ct.beams, 2].min()]).all()
    planar = resample(imgs, table, CODEC, "planar")
    ok = exact < 0.95 * CODEC.max_depth_m
    np.testing.assert_allclose(planar[ok], exact[ok], atol=tol)
    near, planar, exact = near[ok], planar[ok], exact[ok]
    # nearest-pixel error grows like r * dalpha * tan(incidence): at 80 deg it is far above the codec bound
    if incidence_deg >= 80.0:
        assert np.mean(np.abs(near - exact)) > 5 * np.mean(np.abs(planar - exact))


def test_stitched_rig_has_no_seam_artefacts():
    rig = stitched_rig(3, 320, 240, 60.0)          # three cameras, 55 deg apart
    _, e, a = _grid(el=(-15, 15), az=(-70, 70), ne=31, na=281)
    d = beam_directions(e, a)
    table = build_table(rig, d)
    beams = np.concatenate([c.beams for c in table.cameras])
    assert beams.size == d.shape[0] and np.unique(beams).size == d.shape[0]     # no duplicates, no gaps
    assert table.covered.all()
    shapes = [Plane((0.0, -1.0, 0.0), 2.0), Plane((0.0, 0.0, 1.0), 12.0)]    # floor and a wall
    exact = raycast(shapes, np.zeros(3), d)
    rng = resample(_images(shapes, rig), table, CODEC, "planar")
    err = np.abs(rng - exact)
    assert np.isfinite(exact).all() and not np.isnan(rng).any()
    owner = np.empty(d.shape[0], int)
    for k, c in enumerate(table.cameras):
        owner[c.beams] = k
    seam = np.zeros(d.shape[0], bool)
    seam_cols = np.flatnonzero(np.diff(owner.reshape(31, 281), axis=1).any(axis=0))
    grid = seam.reshape(31, 281)
    for c in seam_cols:
        grid[:, max(c - 1, 0):c + 3] = True
    away = ~seam & (exact < 15)
    near_seam = seam & (exact < 15)
    assert near_seam.sum() >= 4 * 31
    assert np.max(err[near_seam]) <= max(4 * BOUND, 2 * np.percentile(err[away], 99.9))


def test_uncovered_beams_are_nan_and_a_small_image_is_refused():
    """Beams outside every camera read the NaN slot of the end-to-end gather; an image smaller than the
    table expects is refused (the gather skips per-index range checks, so the table checks once)."""
    rig = stitched_rig(1, 320, 240, 60.0)
    _, e, a = _grid(el=(-15, 15), az=(-70, 70), ne=11, na=71)            # wider than the one camera
    table = build_table(rig, beam_directions(e, a))
    assert 0 < table.covered.sum() < table.n_beams
    shapes = [Plane((0.0, 0.0, 1.0), 12.0)]
    rng = resample(_images(shapes, rig), table, CODEC, "planar", out=np.zeros(table.n_beams, np.float32))
    assert np.isnan(rng[~table.covered]).all() and np.isfinite(rng[table.covered]).all()
    assert np.array_equal(np.sort(table.source[table.covered]), np.arange(table.covered.sum()))
    small = np.zeros((120, 320, 4), np.uint8)
    with pytest.raises(ValueError, match="image of 38400 pixels"):
        resample([small], table, CODEC, "planar")


def test_offset_lidar_matches_exact_cast_and_is_flagged():
    rig0 = stitched_rig(2, 320, 240, 60.0, pitch_deg=-10.0)
    rig = stitched_rig(2, 320, 240, 60.0, pitch_deg=-10.0, offset_m=(0.15, 0.1, -0.1))
    assert is_offset(rig) and not is_offset(rig0)
    with pytest.raises(ValueError, match="share the sensor origin"):
        build_table(rig, beam_directions(np.zeros(1), np.zeros(1)))
    p, e, a = _grid(el=(-25, 5), az=(-40, 40), ne=31, na=81)
    d = beam_directions(e, a)
    shapes = [Plane((0.0, 1.0, 0.0), -2.5), Box((-1, -2.5, 6), (1, -1.0, 7))]   # floor and a block on it
    exact = raycast(shapes, np.zeros(3), d)
    table = build_offset_table(rig, e, a, pattern_shape(p))
    rng = resample_offset(_images(shapes, rig), table, CODEC)
    ok = np.isfinite(rng) & (exact < 15)
    assert ok.sum() >= 0.95 * np.count_nonzero(exact < 15)
    err = np.abs(rng[ok] - exact[ok])
    assert np.median(err) <= 2 * BOUND
    assert np.mean(err > 0.05) <= 0.01
    # the same through a k-d tree (CSV-like table, no grid layout) gives the same answer
    t2 = build_offset_table(rig, e, a, None)
    assert t2.tree is not None
    rng2 = resample_offset(_images(shapes, rig), t2, CODEC)
    both = np.isfinite(rng2) & ok
    assert both.sum() >= 0.99 * ok.sum()
    np.testing.assert_allclose(rng2[both], rng[both], atol=1e-4)
