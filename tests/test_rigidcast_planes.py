"""The rigid-body ray cast's ranges from the planes of the triangles hit alone (cosim.world.rigidcast
``RigidCaster._ranges``) against its plain reference, every triangle's plane placed (``_ranges_every_plane``): bit
for bit over frames of scenarios on flat and uneven ground (grain surface refitted, stream prisms, the terrain's
patch, tilted bodies); and the transforms packed in one pass as Embree reads them."""
from __future__ import annotations

import functools

import numpy as np
import pytest

from cosim.scenario.loader import load_scenario, packaged_scenarios
from cosim.world import embree_api
from cosim.world.beamtarget import beam_layout
from cosim.world.parts import entity_parts
from cosim.world.scene import scene_from_state
from renderer_proc.projection import world_from_sensor
from renderer_proc.sample import sample_frame

pytest.importorskip("embreex", reason="embreex (the 'fast' extra) is not installed on this platform")


@functools.lru_cache(maxsize=None)
def scenario(name: str):
    return load_scenario(packaged_scenarios()[name])


@pytest.mark.parametrize("name", ["default", "rough_terrain"])
def test_ranges_of_the_hit_planes_equal_the_whole_table_bit_for_bit(name):
    from cosim.world.rigidcast import RigidCaster

    sc = scenario(name)
    caster = RigidCaster(entity_parts(sc))
    seen = []
    fast = caster._ranges

    def both(out, d, lin, trans):
        got = fast(out, d, lin, trans)
        ref = caster._ranges_every_plane(out, d, lin, trans)
        seen.append((got, ref, int((out["geomID"] >= 0).sum())))
        return got

    caster._ranges = both
    try:
        for t in (0.0, 3.0, 7.0, 11.0):
            state, h, stream = sample_frame(sc, t)
            w = world_from_sensor(sc, state)
            caster.cast(scene_from_state(sc, state, h, stream), w[:3, 3],
                        beam_layout(sc.sensor.pattern).directions @ w[:3, :3].T)
    finally:
        caster.close()
    assert len(seen) == 4
    for got, ref, hits in seen:
        assert hits > 1000
        np.testing.assert_array_equal(got.view(np.uint64), ref.view(np.uint64))


def test_packed_transform_is_the_affines_columns():
    """``set_packed_transform`` gives Embree what ``set_transform`` gives it for the same affine, without error."""
    from cosim.world.rigidcast import RigidCaster

    caster = RigidCaster(entity_parts(scenario("default")))
    try:
        inst = caster._protos[0].inst
        affine = np.random.default_rng(3).normal(size=(3, 4))
        embree_api.set_transform(inst, affine)
        plain = inst.buffers[0].copy()
        packed = np.empty((4, 3), np.float32)
        packed[:3] = affine[:, :3].T
        packed[3] = affine[:, 3]
        inst.buffers[0][...] = 0.0
        embree_api.set_packed_transform(inst, packed)
        np.testing.assert_array_equal(inst.buffers[0], plain)
        assert embree_api.api().rtcGetDeviceError(caster._dev) == 0
    finally:
        caster.close()


@pytest.mark.parametrize("nx,ny,cell", [(20, 12, 0.25), (7, 31, 0.4)])
def test_grid_planes_from_kept_terms_equal_the_plain_planes_bit_for_bit(nx, ny, cell):
    """The grain surface's planes from the terms its grid keeps (x, y) and this frame's heights: the planes of
    ``_grid_planes`` bit for bit, for a subset of faces in any order and heights from flat to rough."""
    from cosim.world.heightfield import grid_triangles, grid_vertices
    from cosim.world.rigidcast import _grid_planes, _grid_planes_at, _grid_terms

    rng = np.random.default_rng(nx)
    xy = grid_vertices(nx, ny, cell, nx * cell, ny * cell, np.float64)
    f = grid_triangles(nx, ny).astype(np.int64)
    for z in (np.zeros(len(xy)), rng.uniform(0.0, 2.0, len(xy)), rng.normal(0.0, 1e3, len(xy))):
        v = np.column_stack([xy, z])
        terms = _grid_terms(v, f)
        faces = rng.permutation(len(f))[:len(f) // 3]
        got = _grid_planes_at(terms[faces], z, f[faces])
        np.testing.assert_array_equal(got.view(np.uint64), _grid_planes(v, f[faces]).view(np.uint64))
