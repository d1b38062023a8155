"""Convex solids of the GL beam-native renderer bounded in slices (shaders/solid.geom, docs/lidar.md): long thin
boxes seen diagonally, across the back seam and over the pole, and boxes with a covered top, GL against the exact
ray cast beam for beam; the rectangles cover every beam a box hits, with fewer fragments than one bound."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from cosim.scenario.config.sensing import Codec, Pattern
from cosim.world.beamtarget import beam_layout
from cosim.world.geometry import make_transform
from cosim.world.scene import Boxes, Cylinders, HeightField, Scene
from renderer_proc.codec import decode_depth
from renderer_proc.mock.beam import beam_ranges

pytestmark = pytest.mark.gl

CODEC = Codec()
#: float32 arithmetic of the GL fragment beyond the codec bound, m (as tests/test_beam_native.py)
GL_F32_M = 1e-4
#: the whole sphere but the last 5 deg at each pole (a grid's rows), 3 deg apart; 360 deg of azimuth, 2 deg apart
FULL = Pattern(preset="grid", azimuth_min_deg=-180.0, azimuth_max_deg=180.0, azimuth_count=181,
               elevation_min_deg=-85.0, elevation_max_deg=85.0, elevation_count=57)
#: half a turn ahead, from 75 deg down to 15 deg up, 0.5 deg apart: the covered boxes below the sensor
DOWN = Pattern(preset="grid", azimuth_min_deg=-90.0, azimuth_max_deg=90.0, azimuth_count=361,
               elevation_min_deg=-75.0, elevation_max_deg=15.0, elevation_count=181)
#: how near a box's silhouette a beam may pass and GL and the exact cast disagree whether it hits, m
GRAZE_M = 1e-5
#: the index of the diagonal box of rims()
DIAGONAL = 10
#: a fragment shader that writes every fragment of the geometry shader's rectangles (no test, no discard)
COVER_FRAG = "#version 330\nlayout(location = 0) out uvec4 o_encoded;\nvoid main() { o_encoded = uvec4(1u); }\n"


def rot_y(deg: float) -> np.ndarray:
    a = math.radians(deg)
    return np.array([[math.cos(a), 0.0, math.sin(a)], [0.0, 1.0, 0.0], [-math.sin(a), 0.0, math.cos(a)]])


#: box frame z (its top) along the sensor's +Y (up), x along +X: columns x, y, z of the rotation
Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


def scene_of(poses, halves, hidden=None) -> Scene:
    """Boxes (poses (K, 4, 4), halves (K, 3)) in the sensor frame (world = sensor), a tiny grain patch 50 m
    straight down (below the field), no cylinders."""
    hf = HeightField(make_transform(np.eye(3), (0.0, -50.0, 0.0)), np.zeros((2, 2), np.float32), 0.1, 0.2, 0.2)
    k = len(halves)
    none = Cylinders(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3), np.float32))
    boxes = Boxes(np.asarray(poses, float), np.asarray(halves, float), np.ones((k, 3), np.float32),
                  None if hidden is None else np.asarray(hidden, bool))
    return Scene(boxes, none, hf)


def rims():
    """Long thin boxes (the cart's rims: 6 m x 12 cm x 6 cm) at 2-9 m in every direction and at every yaw and
    tilt, one close ahead rising diagonally across the field (index 10), one across the back seam (behind,
    azimuth +-180 deg) and one over the sensor (holding the +Y pole)."""
    rng = np.random.default_rng(7)
    poses, halves = [], []
    for k in range(10):
        az = math.radians(36.0 * k + 5.0)
        at = rng.uniform(2.0, 9.0) * np.array([-math.sin(az), rng.uniform(-0.8, 0.8), math.cos(az)])
        tilt = np.array([[1.0, 0.0, 0.0], [0.0, math.cos(0.5 * k), -math.sin(0.5 * k)],
                         [0.0, math.sin(0.5 * k), math.cos(0.5 * k)]])
        poses.append(make_transform(rot_y(rng.uniform(0.0, 180.0)) @ tilt, at))
        halves.append((3.0, 0.06, 0.03))
    c = math.sqrt(0.5)
    diagonal = np.array([[c, -c, 0.0], [c, c, 0.0], [0.0, 0.0, 1.0]])          # rising to the left at 45 deg
    poses.append(make_transform(diagonal, (0.0, 0.0, 2.5)))
    halves.append((3.0, 0.06, 0.03))
    poses.append(make_transform(rot_y(10.0), (0.5, 0.3, -4.0)))                 # across the back seam
    halves.append((3.0, 0.06, 0.03))
    poses.append(make_transform(rot_y(40.0), (0.2, 3.0, 0.1)))                  # over the sensor: the pole
    halves.append((3.0, 0.06, 0.03))
    return poses, halves


def covered_box():
    """A floor (3 x 1.5 x 0.05 m half) with its top marked hidden, under a cover plate on that top face, 2.5 m
    below the sensor and 5 m ahead, turned 30 deg, and a second pair far to one side (seen from outside two of
    its side faces)."""
    poses, halves, hidden = [], [], []
    for at, yaw in (((0.5, -2.5, 5.0), 30.0), ((-9.0, -2.0, 4.0), 70.0)):
        r = rot_y(yaw) @ Z_UP
        poses += [make_transform(r, at), make_transform(r, np.asarray(at) + (0.0, 0.15, 0.0))]
        halves += [(3.0, 1.5, 0.05), (3.0, 1.5, 0.1)]
        hidden += [True, False]
    return poses, halves, hidden


def sliced(ctx) -> bool:
    """Whether the boxes are bounded in slices on ``ctx``'s GL (a CPU rasteriser: renderer_proc.gl.beam.slicing_pays);
    elsewhere each solid is one bound, and the tests of fewer fragments do not apply."""
    from renderer_proc.gl.beam import slicing_pays

    return slicing_pays(ctx.info["GL_RENDERER"])


def render(ctx, pattern: Pattern, scene: Scene, *, rgb: bool = False, cover: bool = False, rects: int | None = None,
           monkeypatch=None) -> tuple[np.ndarray, int]:
    """The GL beam-native target of ``scene`` from the origin: decoded ranges (N,) m, or with ``cover`` the
    pixels (N,) bool the solids' rectangles cover; and the fragments shaded (an occlusion query over the solids,
    depth test off with ``cover``). ``rects``: solid.geom's rectangle budget instead of max_rects."""
    import renderer_proc.gl.beam as beam_gl

    if rects is not None:
        monkeypatch.setattr(beam_gl, "max_rects", lambda rgb: rects)
    if cover:
        assemble = beam_gl._assemble
        monkeypatch.setattr(beam_gl, "_assemble",
                            lambda name, *a, **k: COVER_FRAG if name == "solid.frag" else assemble(name, *a, **k))
    lay = beam_layout(pattern)
    r = beam_gl.GLBeamRenderer(lay, CODEC, rgb=rgb, context=ctx)
    if monkeypatch is not None:
        monkeypatch.undo()
    r.set_scene(scene)
    r.draw(0, np.eye(4))
    for fbo, colour in r._frame.clears:
        fbo.clear(*colour, depth=1.0)
    r._frame.draw.use()
    if cover:
        ctx.disable(ctx.DEPTH_TEST)
    q = ctx.query(samples=True)
    with q:
        r._render("box")
        r._render("box_open")
    img = np.zeros(lay.shape + (4,), np.uint8)
    r.read_depth(0, img)
    r.close()
    if cover:
        return lay.beams_of(img.any(axis=2)), q.samples
    return lay.beams_of(decode_depth(img, CODEC)), q.samples


def check_exact(got: np.ndarray, scene: Scene, directions: np.ndarray) -> None:
    """GL ranges (N,) m against the exact cast of ``scene`` along ``directions``: the same beams hit (within
    range) but for grazing ones (the cast with every box grown by :data:`GRAZE_M` hits, shrunk by it misses:
    float32 decides), and each within the codec bound."""
    exact = beam_ranges(scene, np.eye(4), directions)
    b = scene.boxes
    grown, shrunk = (beam_ranges(replace(scene, boxes=replace(b, half_extents=b.half_extents + d)), np.eye(4),
                                 directions) for d in (GRAZE_M, -GRAZE_M))
    differ = np.isfinite(got) != (np.isfinite(exact) & (exact < CODEC.max_depth_m))
    assert np.all(np.isfinite(grown[differ]) & ~np.isfinite(shrunk[differ]))
    assert differ.sum() <= 1e-3 * np.isfinite(exact).sum() + 1
    ok = np.isfinite(got) & np.isfinite(exact)
    assert np.abs(got[ok] - exact[ok]).max() <= CODEC.bound_m + GL_F32_M


@pytest.mark.parametrize("rgb", [False, True], ids=["depth", "shaded"])
def test_sliced_thin_boxes_match_the_exact_cast(ctx, rgb, monkeypatch):
    # 16 rectangles per solid without the shaded output, 13 with it: both budgets, the seam and the pole
    scene = scene_of(*rims())
    lay = beam_layout(FULL)
    got, _ = render(ctx, FULL, scene, rgb=rgb)
    assert np.isfinite(got).sum() > 300
    check_exact(got, scene, lay.directions)
    # and the same bytes as one bound per box: slicing changes which rectangles shade a beam, not its range
    whole, _ = render(ctx, FULL, scene, rgb=rgb, rects=2, monkeypatch=monkeypatch)
    assert np.array_equal(np.isfinite(got), np.isfinite(whole)) and np.array_equal(got[np.isfinite(got)],
                                                                                 whole[np.isfinite(got)])


def test_slices_cover_every_hit_with_fewer_fragments(ctx, monkeypatch):
    poses, halves = rims()
    lay = beam_layout(FULL)
    for k in range(len(halves)):
        scene = scene_of(poses[k:k + 1], halves[k:k + 1])
        hit = np.isfinite(beam_ranges(scene, np.eye(4), lay.directions))
        covered, frags = render(ctx, FULL, scene, cover=True, monkeypatch=monkeypatch)
        _, whole = render(ctx, FULL, scene, cover=True, rects=2, monkeypatch=monkeypatch)    # one bound
        assert hit.any() and np.all(covered[hit]), k                  # every beam the box hits is shaded
        tight, _ = render(ctx, FULL, scene, cover=True, rects=4, monkeypatch=monkeypatch)   # the rest as one
        assert np.all(tight[hit]), k
        assert covered.sum() <= frags <= whole, k
        if k == DIAGONAL and sliced(ctx):                              # a fraction of one bound's fragments
            assert frags < 0.5 * whole, (frags, whole)


def test_covered_top_is_bounded_by_the_side_faces_exactly(ctx, monkeypatch):
    poses, halves, hidden = covered_box()
    lay = beam_layout(DOWN)
    scene = scene_of(poses, halves, hidden)
    got, _ = render(ctx, DOWN, scene)
    check_exact(got, scene, lay.directions)
    # the covered boxes alone: their side faces' rectangles hold every beam entering them not through the top,
    # with under half the fragments of the whole boxes' bounds
    floors = [poses[0], poses[2]], [halves[0], halves[2]]
    covered, frags = render(ctx, DOWN, scene_of(*floors, [True, True]), cover=True, monkeypatch=monkeypatch)
    _, whole = render(ctx, DOWN, scene_of(*floors), cover=True, rects=2, monkeypatch=monkeypatch)
    hit = np.isfinite(beam_ranges(scene_of(*floors), np.eye(4), lay.directions))
    top = np.isfinite(beam_ranges(scene_of([poses[1], poses[3]], [halves[1], halves[3]]), np.eye(4), lay.directions))
    assert np.all(covered[hit & ~top]) and (hit & ~top).sum() > 100
    if sliced(ctx):                      # the covered top's bounds are the sliced geometry shader's (a CPU's GL)
        assert frags < 0.5 * whole, (frags, whole)
        # straight above the covered top no beam can enter the box but through it: nothing is drawn
        above = scene_of([make_transform(Z_UP, (0.0, -2.0, 0.0))], [(3.0, 1.5, 0.05)], [True])
        covered, frags = render(ctx, DOWN, above, cover=True, monkeypatch=monkeypatch)
        assert frags == 0 and not covered.any()
    # seen from below its top plane the box is bounded whole, as any other
    below = scene_of([make_transform(Z_UP, (0.0, 0.6, 4.0))], [(3.0, 1.5, 0.05)], [True])
    got, _ = render(ctx, DOWN, below)
    assert np.isfinite(got).sum() > 100
    check_exact(got, below, lay.directions)


def test_bench_case_reports_the_solid_draws(ctx, tmp_path):
    # the beam_solids case as docs/lidar.md runs it, quick (one frame): fragments and CPU per draw; each draw
    # shades some of the target's 38,400 beams, and fewer than that where the boxes are sliced
    import json
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    subprocess.run([sys.executable, "bench/run.py", "beam_solids", "--quick", "--json", str(tmp_path / "r.json")],
                   cwd=root, check=True, capture_output=True, text=True, timeout=120)
    rows = json.loads((tmp_path / "r.json").read_text())["cases"]["beam_solids"]["samples"]["this"][0]
    for draw in ("boxes", "cylinders"):
        r = rows["solid draws, per frame"][draw]
        assert 1000 < r["fragments"] < (38400 if sliced(ctx) or draw == "cylinders" else 2 * 38400)
        assert min(r["CPU ms"], r["of which geometry ms"]) > 0.0


def test_empty_cart_floor_stays_exact(ctx):
    # the default frame with an empty cart: the floor's covered top lies exactly on the grain surface at height
    # 0, which must still be drawn (the floor is bounded by its side faces only); GL against the exact cast
    from cosim.scenario.config import Scenario
    from cosim.world.scene import scene_from_state
    from renderer_proc.gl.beam import GLBeamRenderer
    from renderer_proc.projection import world_from_sensor
    from renderer_proc.sample import sample_frame

    sc = Scenario(format_version=1, sensor={"method": "beam_native"})
    lay = beam_layout(sc.sensor.pattern)
    state, heights, stream = sample_frame(sc)
    scene = scene_from_state(sc, state, np.zeros_like(heights), stream)
    pose = world_from_sensor(sc, state)
    assert scene.boxes.hidden_top is not None and scene.boxes.hidden_top.any()
    r = GLBeamRenderer(lay, CODEC, context=ctx)
    r.set_scene(scene)
    r.draw(0, pose)
    img = np.zeros(lay.shape + (4,), np.uint8)
    r.read_depth(0, img)
    r.close()
    got, exact = lay.beams_of(decode_depth(img, CODEC)), beam_ranges(scene, pose, lay.directions)
    assert np.array_equal(np.isfinite(got), np.isfinite(exact) & (exact < CODEC.max_depth_m))
    ok = np.isfinite(got)
    assert ok.sum() > 0.9 * lay.n_beams
    assert np.abs(got[ok] - exact[ok]).max() <= CODEC.bound_m + GL_F32_M


def test_boxes_are_sliced_on_cpu_rasterisers_only(ctx):
    from renderer_proc.gl.beam import slicing_pays
    # llvmpipe shades every fragment on the CPU: slicing pays there; a GPU draws the boxes unsliced (the same
    # bytes, test above), and NVIDIA's compiler is never given the slicing loop it crashes on
    assert slicing_pays(ctx.info["GL_RENDERER"]) == ("llvmpipe" in ctx.info["GL_RENDERER"])
    assert slicing_pays("llvmpipe (LLVM 15.0.6, 256 bits)")
    assert not slicing_pays("NVIDIA H100 80GB HBM3/PCIe/SSE2")
    assert not slicing_pays("AMD Radeon RX 7900 XTX (radeonsi, navi31, LLVM 15.0.7, DRM 3.54)")
