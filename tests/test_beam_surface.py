"""The grain surface's quad path in the GL beam-native renderer (renderer_proc/gl/surface.py,
shaders/beam_quad.*): SurfaceMesh.quads is SurfaceMesh.triangles in pairs, and rough height fields (steep steps,
grazing beams, beams straight down across the back seam) are drawn beam for beam as the exact ray cast, with no
beam the surface is hit by left unwritten (docs/lidar.md)."""
from __future__ import annotations

import numpy as np
import pytest

from cosim.scenario.config import Scenario
from cosim.scenario.config.sensing import Codec, Pattern
from cosim.world.beamtarget import beam_layout
from cosim.world.geometry import make_transform
from cosim.world.heightfield import padded_heights
from cosim.world.scene import Boxes, Cylinders, HeightField, Scene, scene_from_state
from renderer_proc.codec import decode_depth
from renderer_proc.gl.hfmesh import MERGE_BLOCK, SurfaceMesh
from renderer_proc.mock.beam import beam_ranges
from renderer_proc.projection import world_from_sensor
from renderer_proc.sample import sample_frame

CODEC = Codec()
#: float32 arithmetic of the GL fragment beyond the codec bound, m (as tests/test_beam_native.py)
GL_F32_M = 1e-4
#: grid frame -> sensor frame (X right, Y up, Z forward): grid x along Z, grid y along X, grid z (up) along Y
GRID_AXES = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])


def rough(shape, seed: int, step_m: float = 0.0, flat_frac: float = 0.5) -> np.ndarray:
    """(nx, ny) float32 m: random heights, a random ``flat_frac`` of the merge blocks flat at 0 (SurfaceMesh's
    blocks of MERGE_BLOCK quads over the padded vertex grid: vertex a is cell a - 1), random vertical steps of
    ``step_m`` on 20 % of the cells, and the outermost cells at 0, the lowest height (the ray cast's height field
    is a solid whose sides a cart's walls hide; here nothing would, and a side face the GL surface does not have
    would be seen)."""
    rng = np.random.default_rng(seed)
    h = rng.uniform(0.0, 0.3, shape) + step_m * (rng.random(shape) < 0.2)
    for i in range(shape[0] // MERGE_BLOCK + 1):
        for j in range(shape[1] // MERGE_BLOCK + 1):
            if rng.random() < flat_frac:                         # the block's vertices: cells 4 i - 1 .. 4 i + 3
                a0, b0 = max(MERGE_BLOCK * i - 1, 0), max(MERGE_BLOCK * j - 1, 0)
                h[a0:MERGE_BLOCK * (i + 1), b0:MERGE_BLOCK * (j + 1)] = 0.0
    h[[0, -1]] = 0.0
    h[:, [0, -1]] = 0.0
    return h.astype(np.float32)


def surface_scene(heights: np.ndarray, corner_sensor: tuple[float, float, float], cell: float = 0.1) -> Scene:
    """The height field alone (no solids), grid corner (0, 0, 0) at ``corner_sensor`` in the sensor frame."""
    nx, ny = heights.shape
    hf = HeightField(make_transform(GRID_AXES, corner_sensor), heights, cell, nx * cell, ny * cell)
    none = Cylinders(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3), np.float32))
    return Scene(Boxes(np.zeros((0, 4, 4)), np.zeros((0, 3)), np.zeros((0, 3), np.float32)), none, hf)


def render(ctx, pattern: Pattern, scene: Scene, pose: np.ndarray) -> dict[str, np.ndarray]:
    """Encoded and shaded images of the GL renderer's quad and triangle paths, the exact ranges (N,) m."""
    from renderer_proc.gl.beam import GLBeamRenderer

    lay = beam_layout(pattern)
    out = {"exact": beam_ranges(scene, pose, lay.directions), "layout": lay}
    for name, quads in (("quads", True), ("triangles", False)):
        r = GLBeamRenderer(lay, CODEC, context=ctx, rgb=True, surface_quads=quads)
        out[name], out[name + "_rgb"] = (np.zeros(lay.shape + (4,), np.uint8) for _ in range(2))
        r.set_scene(scene)
        r.draw(0, pose)
        r.read_depth(0, out[name])
        r.read_rgb(0, out[name + "_rgb"])
        r.close()
    return out


def check_exact(got: dict) -> int:
    """GL's quad path against the exact cast beam for beam: the same beams written (coverage), each within the
    codec's bound plus float32; returns how many beams the surface covers."""
    lay, exact = got["layout"], got["exact"]
    gl = lay.beams_of(decode_depth(got["quads"], CODEC))
    hit = np.isfinite(exact) & (exact < CODEC.max_depth_m)
    assert np.array_equal(np.isfinite(gl), hit), (np.count_nonzero(hit & ~np.isfinite(gl)),
                                                   np.count_nonzero(np.isfinite(gl) & ~hit))
    assert np.abs(gl[hit] - exact[hit]).max() <= CODEC.bound_m + GL_F32_M
    assert np.mean(np.all(got["quads"] == got["triangles"], axis=2)) > 0.999       # the two paths: same bytes
    shade = np.abs(got["quads_rgb"].astype(int) - got["triangles_rgb"].astype(int)).max(axis=2)
    assert np.mean(shade <= 1) > 0.999                          # and the same shading (the hit triangle's normal)
    return int(hit.sum())


@pytest.mark.parametrize("seed", range(4))
def test_quads_are_the_triangles_in_pairs(seed):
    h = rough((23, 13), seed, flat_frac=0.6)
    mesh = SurfaceMesh(23, 13, 0.1, 2.3, 1.3)
    hp = padded_heights(h)
    tri, _ = mesh.triangles(hp)
    quads, changed = mesh.quads(hp)
    assert changed and quads.shape[1] == 4 and not mesh.quads(hp)[1]
    pairs = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    pairs = pairs[pairs[:, 2] != pairs[:, 1]]                   # a fan's odd triangle has a degenerate partner
    assert len(pairs) == len(tri) and len(quads) <= (len(tri) + 1) // 2 + mesh.blocks[0] * mesh.blocks[1]
    assert sorted(map(tuple, pairs)) == sorted(map(tuple, tri))   # the same triangles, corners in the same order
    flat = mesh.flat_blocks(hp)
    assert 0 < flat.sum() < flat.size                           # both kinds of block were exercised


@pytest.mark.gl
@pytest.mark.parametrize("seed", range(3))
def test_rough_steps_seen_at_grazing_incidence_match_the_exact_cast(ctx, seed):
    # a 6 x 3 m field of random heights and 0.8 m steps from 1 m above its highest point and 1.5 m behind it: the
    # far part is seen at a few degrees, the steps' faces edge-on and from the front, parts hidden behind them
    h = rough((60, 30), seed, step_m=0.8)
    scene = surface_scene(h, (-1.5, -1.0 - float(h.max()), 1.5))
    pattern = Pattern(preset="grid", azimuth_min_deg=-60, azimuth_max_deg=60, azimuth_count=240,
                      elevation_min_deg=-60, elevation_max_deg=5, elevation_count=160)
    assert check_exact(render(ctx, pattern, scene, np.eye(4))) > 10_000


@pytest.mark.gl
def test_straight_down_across_the_back_seam_and_the_pole(ctx):
    # the sensor 1.2 m above the middle of a rough field, a full turn of beams down to 89.5 deg: quads under it
    # hold the pole (-Y), quads behind it cross the back seam
    h = rough((40, 40), 7, step_m=0.3, flat_frac=0.0)
    scene = surface_scene(h, (-1.98, -1.2 - float(h.max()), -2.03))
    pattern = Pattern(preset="grid", azimuth_min_deg=-180, azimuth_max_deg=180, azimuth_count=240,
                      elevation_min_deg=-89.5, elevation_max_deg=-20, elevation_count=160)
    assert check_exact(render(ctx, pattern, scene, np.eye(4))) > 25_000


@pytest.mark.gl
def test_rough_mid_run_heap_in_the_default_scene(ctx):
    # the default scene and LiDAR with every merge block rough (nothing merged): the vehicles, ground and stream
    # occlude and are occluded by the surface as in the exact cast
    sc = Scenario(format_version=1, sensor={"method": "beam_native"})
    state, heights, stream = sample_frame(sc, 2.0)
    heights = (heights + rough(heights.shape, 3, step_m=0.1, flat_frac=0.0)).astype(np.float32)
    scene = scene_from_state(sc, state, heights, stream)
    got = render(ctx, sc.sensor.pattern, scene, world_from_sensor(sc, state))
    check_exact(got)


@pytest.mark.gl
def test_surface_benchmark_counts_fewer_fragments_for_quads(ctx):
    # the beam_surface case on one frame of each kind: the quads shade fewer fragments than the triangles (the
    # counts are exact, not timings), and the two paths' images agree
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
    from cases.gl_draws import surface_paths

    res = surface_paths(frames=1, span=8.0, reps=1, context=ctx)
    rows = res["grain surface draw, per frame"]
    ratio = {kind: rows[f"{kind}, quads / triangles"]["fragments shaded"] for kind in ("sample", "rough")}
    assert all(0.0 < v < 0.75 for v in ratio.values()), ratio
    checks = res["quads against triangles, checks"]
    assert all(c["% beams byte-identical (worst frame)"] > 99.0 for c in checks.values()), checks


@pytest.mark.gl
def test_unchanged_heights_are_not_uploaded_again_and_changed_ones_are(ctx):
    # Surface.upload writes the heights only when their bytes change: frames alternating between two height fields
    # (and repeating one) give each field's own image, and a repeat writes nothing
    from renderer_proc.gl.beam import GLBeamRenderer

    pattern = Pattern(preset="grid", azimuth_min_deg=-60, azimuth_max_deg=60, azimuth_count=120,
                      elevation_min_deg=-60, elevation_max_deg=5, elevation_count=80)
    lay = beam_layout(pattern)
    a, b = rough((30, 20), 1, step_m=0.2), rough((30, 20), 2, step_m=0.2)
    r = GLBeamRenderer(lay, CODEC, context=ctx)
    writes = []
    r._surface._upload_heights = (lambda f: lambda hp: (writes.append(1), f(hp)))(r._surface._upload_heights)
    images = []
    for h in (a, b, b, a, a):
        img = np.zeros(lay.shape + (4,), np.uint8)
        r.set_scene(surface_scene(h, (-1.0, -1.0 - float(h.max()), 1.0)))
        r.draw(0, np.eye(4))
        r.read_depth(0, img)
        images.append(img)
    r.close()
    assert len(writes) == 3                                        # a, b, a: the repeats wrote nothing
    assert not np.array_equal(images[0], images[1])
    assert np.array_equal(images[1], images[2]) and np.array_equal(images[0], images[3])
    assert np.array_equal(images[3], images[4])
