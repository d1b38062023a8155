"""The field surface (cosim.world.terrain) and the machines and the grain on it (dynamics_proc.vehicles.ground,
dynamics_proc.grain.tilt): closed forms on a known slope, the roughness's statistics, the repose surface and the
spill edge in a tilted cart, mass balance and determinism on rough ground."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from cosim.runtime.outcome import judge
from cosim.scenario.config import Scenario
from cosim.world.geometry import body_pose
from cosim.world.raycast import raycast
from cosim.world.scene import scene_from_state
from cosim.world.terrain import rough_field, terrain_of
from dynamics_proc.closed_loop import simulate
from dynamics_proc.grain.fill import GrainGrid, volume
from dynamics_proc.grain.tilt import Tilt, deposit_tilted, l1_envelope, settle, tilt_of, tilted_cap
from dynamics_proc.model import ModelParams, initial_world, signals
from dynamics_proc.summary import summarize
from dynamics_proc.vehicles.ground import machine_poses, planar_poses


def scen(terrain=None, **kw) -> Scenario:
    d = {"format_version": 1, "feedback": "ground_truth", "renderer": "none", "duration_s": 120.0,
         "terrain": terrain or {}}
    d.update(kw)
    return Scenario.model_validate(d)


def test_the_roughness_has_its_stated_variance_and_correlation_length():
    rms, corr, cell, n = 0.05, 2.0, 0.25, 256
    var, c_at_l = [], []
    for seed in range(8):
        f = rough_field(rms, corr, n, cell, seed)
        var.append(np.mean(f * f))
        lag = int(round(corr / cell))
        c_at_l += [np.mean(f * np.roll(f, lag, a)) / np.mean(f * f) for a in (0, 1)]
    assert np.mean(var) == pytest.approx(rms ** 2, rel=0.05)
    assert np.mean(c_at_l) == pytest.approx(math.exp(-1.0), abs=0.03)        # C(L) = rms^2 / e
    assert np.array_equal(rough_field(rms, corr, 64, cell, 3), rough_field(rms, corr, 64, cell, 3))   # seeded


def test_flat_ground_is_no_terrain_and_its_fields_are_exactly_zero():
    s = scen()
    assert terrain_of(s) is None and ModelParams.from_scenario(s).stance is None
    p = ModelParams.from_scenario(s)
    sig = signals(initial_world(s, p), p)
    assert all(sig[f"{n}_{f}"] == 0.0 for n in ("combine", "tractor", "cart") for f in ("z_m", "roll_rad",
                                                                                             "pitch_rad"))


@pytest.mark.parametrize("heading_deg", [0.0, 30.0])
def test_a_cart_on_a_known_slope_stands_on_its_plane(heading_deg):
    grade, cross = 0.04, 0.06
    s = scen({"grade_pct": 100 * grade, "cross_slope_pct": 100 * cross}, combine={"heading_deg": heading_deg})
    p = ModelParams.from_scenario(s)
    w = initial_world(s, p)
    _, _, cart = machine_poses(p.stance, *planar_poses(w.x, p.vehicles))
    x, y, yaw, z, roll, pitch = cart
    a = grade * math.cos(yaw) + cross * math.sin(yaw)         # the plane's slope along the cart's axes
    b = -grade * math.sin(yaw) + cross * math.cos(yaw)
    assert pitch == pytest.approx(-math.atan(a), abs=1e-12)
    assert roll == pytest.approx(math.atan2(b, math.sqrt(1 + a * a)), abs=1e-12)
    assert z == pytest.approx(grade * x + cross * y, abs=1e-12)
    # the cart's floor plane is parallel to the ground: its normal is the plane's
    n = body_pose(*cart)[:3, 2]
    assert n == pytest.approx(np.array([-grade, -cross, 1.0]) / math.sqrt(1 + grade ** 2 + cross ** 2), abs=1e-12)


def test_the_drawn_ground_is_the_surface_the_wheels_stand_on():
    s = scen({"roughness_rms_m": 0.05, "grade_pct": 2.0})
    t = terrain_of(s)
    name, verts, faces, origin = t.mesh((10.0, 3.0))
    rng = np.random.default_rng(0)
    tri = faces[rng.integers(len(faces), size=200)]
    w = rng.dirichlet(np.ones(3), size=200)
    pts = np.einsum("kj,kji->ki", w, verts[tri]) + origin
    assert t.height(pts[:, 0], pts[:, 1]) == pytest.approx(pts[:, 2], abs=1e-12)
    # and the ray caster finds it where the scene puts it
    p = ModelParams.from_scenario(s)
    state = signals(initial_world(s, p), p)
    state["stream_points"] = 0
    scene = scene_from_state(s, state, np.asarray(initial_world(s, p).heights, np.float32), np.zeros((64, 4)))
    assert scene.ground_box is None and scene.meshes[-1].name.startswith("terrain@")
    xy = np.array([[state["cart_x_m"] + 9.0, state["cart_y_m"] - 7.0]])
    hit = raycast(scene, np.c_[xy, [[20.0]]], np.array([[0.0, 0.0, -1.0]]))
    assert 20.0 - hit[0] == pytest.approx(float(t.height(xy[0, 0], xy[0, 1])), abs=1e-9)


def test_a_patch_is_made_once_while_the_cart_stays_in_its_step():
    """The patch's arrays are shared (read-only) by the frames within its quarter step, and a new one is made,
    equal to one made afresh, when the cart moves on."""
    s = scen({"roughness_rms_m": 0.05, "grade_pct": 2.0})
    t = terrain_of(s)
    first = t.mesh((10.0, 3.0))
    again = t.mesh((10.0 + 1e-3, 3.0))
    assert again[0] == first[0] and all(a is b for a, b in zip(again[1:], first[1:]))
    assert not first[1].flags.writeable
    moved = t.mesh((10.0 + t.render_extent_m / 2.0, 3.0))
    assert moved[0] != first[0]
    fresh = replace(t, _patch={}).mesh((10.0 + t.render_extent_m / 2.0, 3.0))
    for a, b in zip(moved[1:], fresh[1:]):
        np.testing.assert_array_equal(a, b)


def test_the_min_plus_envelope_is_the_brute_force_one():
    rng = np.random.default_rng(1)
    u = rng.random((7, 5))
    step = 0.1
    ii, jj = np.indices(u.shape)
    brute = np.array([[np.min(u + step * (np.abs(ii - i) + np.abs(jj - j))) for j in range(5)] for i in range(7)])
    assert l1_envelope(u, step) == pytest.approx(brute, abs=1e-12)


def _grid() -> GrainGrid:
    return GrainGrid.from_scenario(scen())


def test_the_tilted_cap_is_the_lowest_cone_over_the_wall_tops_and_lowest_on_the_low_side():
    g = _grid()
    tilt = Tilt(0.02, -0.05, math.sqrt(1 - 0.02 ** 2 - 0.05 ** 2))       # floor falls towards grid y = W
    cap = tilted_cap(g, tilt)
    x, y = g.centres()
    # brute force over wall-top points 1 mm apart
    t = np.arange(0.0, g.length_m + 1e-9, 1e-3)
    r = np.arange(0.0, g.width_m + 1e-9, 1e-3)
    walls = np.concatenate([np.c_[t, 0 * t], np.c_[t, 0 * t + g.width_m], np.c_[0 * r, r], np.c_[0 * r + g.length_m, r]])
    u_wall = tilt.sx * walls[:, 0] + tilt.sy * walls[:, 1] + tilt.nz * g.depth_m
    for i, j in [(0, 0), (30, 15), (59, 29), (10, 28), (45, 1)]:
        cone = u_wall + g.tan_repose * np.hypot(walls[:, 0] - x[i], walls[:, 1] - y[j])
        want = (cone.min() - tilt.sx * x[i] - tilt.sy * y[j]) / tilt.nz
        assert cap[i, j] == pytest.approx(want, abs=2e-4)
    u_cap = tilt.floor(g) + tilt.nz * cap                                 # in world heights the low side is lower
    assert u_cap[:, -1].mean() < u_cap[:, 0].mean() - 0.1


def test_a_tilted_cart_filled_over_the_top_spills_over_the_low_side_and_stays_relaxed():
    g = _grid()
    tilt = Tilt(0.0, -0.06, math.sqrt(1 - 0.06 ** 2))      # the floor falls towards grid y = W
    cap = tilted_cap(g, tilt)
    h = np.full((g.nx, g.ny), 1.0)
    v0, delivered, spilled = volume(h, g), 0.0, 0.0
    while spilled == 0.0:                                   # fill at the middle until the first grain spills
        h, spilled = deposit_tilted(h, 3.0, 1.5, 0.1, g, tilt, cap)
        delivered += 0.1
    full = np.isclose(h, cap, atol=1e-9)                    # the heap's flank lies on the cap up to the wall it
    assert full[:, -1].any() and not (full[:, 0].any() or full[0].any() or full[-1].any())   # spills over: the low
    for _ in range(100):                                    # and then 10 m^3 more
        h, s = deposit_tilted(h, 3.0, 1.5, 0.1, g, tilt, cap)
        delivered, spilled = delivered + 0.1, spilled + s
    assert volume(h, g) + spilled == pytest.approx(v0 + delivered, rel=1e-12)
    assert spilled > 1.0
    u = tilt.floor(g) + tilt.nz * h                        # relaxed relative to gravity, not to the floor
    step = g.tan_repose * g.cell_m
    assert np.abs(np.diff(u, axis=0)).max() <= step + 1e-9 and np.abs(np.diff(u, axis=1)).max() <= step + 1e-9
    assert np.abs(np.diff(h, axis=1)).max() > step          # relative to the floor it is steeper on one side


def test_a_heap_tilted_further_slides_to_the_repose_slope_without_losing_grain():
    g = _grid()
    level = Tilt(0.0, 0.0, 1.0)
    h = np.full((g.nx, g.ny), 0.8)
    h, _ = deposit_tilted(h, 3.0, 1.5, 6.0, g, Tilt(0.0, -1e-9, 1.0), tilted_cap(g, Tilt(0.0, -1e-9, 1.0)))
    assert tilt_of(np.eye(4)) is None and level.nz == 1.0
    steep = Tilt(0.05, 0.0, math.sqrt(1 - 0.05 ** 2))
    v0 = volume(h, g)
    new, spill = settle(h, g, steep, tilted_cap(g, steep))
    assert volume(new, g) + spill == pytest.approx(v0, rel=1e-12)
    u = steep.floor(g) + steep.nz * new
    step = g.tan_repose * g.cell_m
    assert np.abs(np.diff(u, axis=0)).max() <= step + 1e-9 and np.abs(np.diff(u, axis=1)).max() <= step + 1e-9
    assert not np.array_equal(new, h)                      # something slid


@pytest.mark.parametrize("terrain", [{"cross_slope_pct": 5.0}, {"roughness_rms_m": 0.05, "grade_pct": -3.0}])
def test_a_ground_truth_run_on_uneven_ground_fills_with_exact_mass_balance_and_repeats(terrain):
    s = scen(terrain, duration_s=100.0)
    r = simulate(s)
    se = r.series
    sm = summarize(s, se, r.heights)
    assert sm["mass_balance"]["relative_error"] <= 1e-12
    assert judge(s, {**sm, "completed": True}, se)["status"] == "filled"
    roll = np.degrees(np.abs(se["dyn_state.cart_roll_rad"]))
    assert roll.max() > 0.5                                # the cart really tilts
    again = simulate(s)
    assert all(np.array_equal(se[k], again.series[k], equal_nan=True) for k in se)


@pytest.mark.parametrize("terrain", [{"grade_pct": 5.0}, {"roughness_rms_m": 0.04}])
def test_the_mock_renderers_rigid_cast_agrees_with_the_exact_reference_on_uneven_ground(terrain):
    pytest.importorskip("embreex")
    from cosim.world.camera import beam_directions
    from cosim.world.fastcast import cast_from, make_caster
    from cosim.world.parts import entity_parts
    from cosim.world.patterns import beam_table
    from renderer_proc.projection import world_from_sensor

    s = scen(terrain, renderer="mock")
    p = ModelParams.from_scenario(s)
    w = initial_world(s, p)
    state = signals(w, p)
    caster = make_caster(entity_parts(s))
    el, az = beam_table(s.sensor.pattern)
    for shift in (0.0, 13.0):                              # the terrain's patch moves on between the two
        st = {**state, "stream_points": 0, **{f"{n}_x_m": state[f"{n}_x_m"] + shift for n in ("combine", "tractor",
                                                                                             "cart")}}
        scene = scene_from_state(s, st, np.asarray(w.heights, np.float32), np.zeros((64, 4)))
        ws = world_from_sensor(s, st)
        d = beam_directions(el, az) @ ws[:3, :3].T
        a, b = caster.cast(scene, ws[:3, 3], d), cast_from(scene, ws[:3, 3], d)
        hit = np.isfinite(a)
        assert np.array_equal(hit, np.isfinite(b)) and np.abs(a[hit] - b[hit]).max() < 1e-9
    caster.close()


def test_a_stream_of_no_radius_is_nothing_to_the_rigid_cast_as_to_the_reference():
    """The last frame of a run-out can end at flow 0 with grain still in the air: its rows have radius 0."""
    pytest.importorskip("embreex")
    from cosim.world.camera import beam_directions
    from cosim.world.fastcast import cast_from, make_caster
    from cosim.world.parts import entity_parts
    from cosim.world.patterns import beam_table
    from renderer_proc.projection import world_from_sensor

    s = scen({"cross_slope_pct": 4.0}, renderer="mock")
    p = ModelParams.from_scenario(s)
    w = initial_world(s, p)
    state = {**signals(w, p), "stream_points": 64}
    stream = np.array(w.stream, np.float32)
    stream[:, 3] = 0.0
    scene = scene_from_state(s, state, np.asarray(w.heights, np.float32), stream)
    ws = world_from_sensor(s, state)
    el, az = beam_table(s.sensor.pattern)
    d = beam_directions(el, az) @ ws[:3, :3].T
    caster = make_caster(entity_parts(s))
    a, b = caster.cast(scene, ws[:3, 3], d), cast_from(scene, ws[:3, 3], d)
    caster.close()
    hit = np.isfinite(a)
    assert np.array_equal(hit, np.isfinite(b)) and np.abs(a[hit] - b[hit]).max() < 1e-9


def test_a_height_map_file_is_the_ground_and_holds_its_edges(tmp_path):
    import json

    heights = np.add.outer(np.arange(5) * 0.1, np.arange(4) * 0.02)   # z = 0.1 i + 0.02 j every 2 m
    np.save(tmp_path / "field.npy", heights)
    s = Scenario.model_validate_json(json.dumps({"format_version": 1, "terrain": {
        "height_map_file": str(tmp_path / "field.npy"), "cell_m": 2.0, "origin_xy_m": [-4.0, -2.0]}}))
    t = terrain_of(s)
    assert t.height(-4.0 + 2.0 * 3, -2.0 + 2.0 * 2) == pytest.approx(0.34)           # a sample
    assert t.height(-4.0 + 3.0, -2.0 + 1.0) == pytest.approx(0.15 + 0.01)            # linear between samples
    assert t.height(100.0, -50.0) == pytest.approx(0.4)                               # beyond: the edge holds
