"""The GL renderer against closed forms and against the mock (numpy ray caster) on the cart scene."""
from __future__ import annotations

import math

import numpy as np
import pytest

from cosim.errors import RendererUnavailable
from cosim.scenario.config import Scenario
from cosim.scenario.config.sensing import Codec
from cosim.world.camera import Pinhole, Rig, RigCamera
from cosim.world.geometry import make_transform, rot_x, rot_y
from cosim.world.scene import Boxes, Cylinders, HeightField, Scene, scene_from_state
from renderer_proc.codec import decode_depth, encode_depth
from renderer_proc.mock.backend import MockRenderer
from renderer_proc.projection import camera_poses
from renderer_proc.sample import sample_frame

pytestmark = pytest.mark.gl
CODEC = Codec()
#: float32 interpolation of view-space z, m: far below the codec bound
Z_TOL_M = 2e-5
#: relative float32 error of perspective-correct interpolation across triangles hundreds of metres wide
#: (the ground slab); measured 1.1e-5 on a 2 km face, 1e-6 on a 200 m face
Z_TOL_REL = 2e-5


def renderer(ctx, rig, codec=CODEC, **kw):
    from renderer_proc.gl.backend import GLRenderer
    return GLRenderer(rig, codec, context=ctx, **kw)


def one_cam(w=96, h=64, hfov_deg=60.0) -> Rig:
    return Rig((RigCamera("cam0", Pinhole(w, h, math.radians(hfov_deg)), np.eye(4)),))


def box_scene(world_from_box, half) -> Scene:
    """A single box in an otherwise empty scene (the grain field is tiny and behind the camera)."""
    hf = HeightField(make_transform(np.eye(3), (0.0, 0.0, -5.0)), np.zeros((2, 2), np.float32), 0.1, 0.2, 0.2)
    return Scene(Boxes(world_from_box[None], np.array([half], float), np.ones((1, 3), np.float32)),
                 Cylinders(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3), np.float32)), hf)


def render(r, scene, pose=None, k=0):
    pose = np.eye(4) if pose is None else pose
    cam = r.rig.cameras[k].intrinsics
    out = np.zeros((cam.height, cam.width, 4), np.uint8)
    r.set_scene(scene)
    r.draw(k, pose)
    r.read_depth(k, out)
    return out


@pytest.mark.parametrize("dist", [0.7, 3.3, 12.0, 41.7])
def test_fronto_parallel_plane_decodes_to_distance(ctx, dist):
    """Camera identity pose: camera Z is world z here. A box face at z = dist fills the view."""
    r = renderer(ctx, one_cam(), float_depth=True)
    scene = box_scene(make_transform(np.eye(3), (0.0, 0.0, dist + 100.0)), (1e3, 1e3, 100.0))
    img = render(r, scene)
    assert np.all(img[..., 3] == 255)
    d = decode_depth(img, CODEC)
    assert np.abs(d - dist).max() <= CODEC.bound_m + Z_TOL_M
    zf = np.zeros((64, 96), np.float32)
    r.read_zf(0, zf)
    np.testing.assert_allclose(zf, dist, atol=Z_TOL_M)
    r.close()


@pytest.mark.parametrize("tilt_deg,axis", [(30.0, "x"), (-50.0, "y"), (65.0, "x")])
def test_tilted_plane_matches_planar_depth_at_pixel_centres(ctx, tilt_deg, axis):
    """Plane n . P = c (camera frame): planar depth at pixel (u, v) is Z = c / (n . ((u - w/2)/f, (h/2 - v)/f, 1)),
    which checks the projection at the centre, edges and corners at once."""
    cam = Pinhole(96, 64, math.radians(70.0))
    r = renderer(ctx, Rig((RigCamera("cam0", cam, np.eye(4)),)))
    rot = rot_x(math.radians(tilt_deg)) if axis == "x" else rot_y(math.radians(tilt_deg))
    n = rot @ np.array([0.0, 0.0, 1.0])
    c = 4.0
    thick = 50.0
    centre = n * (c + thick)
    img = render(r, box_scene(make_transform(rot, centre), (400.0, 400.0, thick)))
    uu, vv = cam.pixel_centres()
    ray = np.stack([(uu - 48.0) / cam.f, (32.0 - vv) / cam.f, np.ones_like(uu)], axis=-1)
    z = c / (ray @ n)
    valid = (z > 0) & (z < CODEC.max_depth_m)
    d = decode_depth(img, CODEC)
    np.testing.assert_array_equal(np.isfinite(d), valid)
    assert np.all(np.abs(d - z)[valid] <= CODEC.bound_m + Z_TOL_M + Z_TOL_REL * z[valid])
    # the corner pixels are checked too
    for j, i in [(0, 0), (0, 95), (63, 0), (63, 95), (32, 48)]:
        if valid[j, i]:
            assert abs(d[j, i] - z[j, i]) <= CODEC.bound_m + Z_TOL_M
    r.close()


def test_box_edges_at_projected_corners(ctx):
    """A box seen face-on: its face covers exactly the pixels whose centres project inside it."""
    cam = Pinhole(80, 60, math.radians(60.0))
    r = renderer(ctx, Rig((RigCamera("cam0", cam, np.eye(4)),)))
    img = render(r, box_scene(make_transform(np.eye(3), (0.37, -0.21, 6.5)), (0.8, 0.5, 0.5)))
    uu, vv = cam.pixel_centres()
    x, y = (uu - 40.0) / cam.f * 6.0, (30.0 - vv) / cam.f * 6.0
    inside = (np.abs(x - 0.37) < 0.8) & (np.abs(y + 0.21) < 0.5)
    np.testing.assert_array_equal(img[..., 3] == 255, inside)
    np.testing.assert_allclose(decode_depth(img, CODEC)[inside], 6.0, atol=CODEC.bound_m + Z_TOL_M)
    assert np.all(img[~inside] == 0)
    r.close()


def test_out_of_range_and_background_are_invalid(ctx):
    r = renderer(ctx, one_cam())
    img = render(r, box_scene(make_transform(np.eye(3), (0.0, 0.0, 150.0)), (1e3, 1e3, 100.0)))
    assert np.all(img == 0)                           # face at 50 m = alpha: out of range, never a depth
    r.close()


def test_bytes_equal_numpy_encoder_both_gamma_modes(ctx):
    for codec in (CODEC, Codec(gamma_mode="mishandled"), Codec(alpha_cm=2540.0, beta_cm=10.0)):
        r = renderer(ctx, one_cam(), codec=codec, float_depth=True)
        rot = rot_x(math.radians(40.0))
        img = render(r, box_scene(make_transform(rot, rot @ np.array([0.0, 0.0, 53.0])), (1e3, 1e3, 50.0)))
        zf = np.zeros((64, 96), np.float32)
        r.read_zf(0, zf)
        ref = encode_depth(zf.astype(np.float64), codec)
        # float32 z on a byte boundary may round either way: allow 1 in B on a handful of pixels
        diff = np.abs(img.astype(int) - ref.astype(int))
        assert np.all(diff[..., [0, 1, 3]] == 0)
        assert np.mean(diff[..., 2] > 0) < 0.01 and diff[..., 2].max() <= 1
        r.close()


def test_read_into_fills_destination_in_place(ctx):
    r = renderer(ctx, one_cam())
    buf = bytearray(64 * 96 * 4 + 64)
    dest = np.frombuffer(buf, np.uint8, 64 * 96 * 4, 64).reshape(64, 96, 4)
    before = dest.__array_interface__["data"][0]
    r.set_scene(box_scene(make_transform(np.eye(3), (0.0, 0.0, 105.0)), (1e3, 1e3, 100.0)))
    r.draw(0, np.eye(4))
    r.read_depth(0, dest)
    assert dest.__array_interface__["data"][0] == before
    assert np.shares_memory(dest, np.frombuffer(buf, np.uint8))
    assert np.all(np.frombuffer(buf, np.uint8, 64 * 96 * 4, 64).reshape(64, 96, 4)[..., 3] == 255)
    with pytest.raises(ValueError, match="C-contiguous"):
        r.read_depth(0, np.zeros((96, 64, 4), np.uint8))
    with pytest.raises(ValueError, match="without the rgb output"):
        r.read_rgb(0, np.zeros((64, 96, 4), np.uint8))
    r.close()


@pytest.mark.parametrize("t_s", [0.0, 600.0])
def test_gl_and_mock_agree_on_cart_scene(ctx, t_s):
    """>= 99 % of the pixels valid in both decode within 1 cm of each other (depth edges excepted), and both
    mark the same pixels invalid: same geometry, same conventions. At t = 600 s the machines are 1.2 km from
    the world origin (float32 on the GPU keeps its precision: coordinates are relative to the cart)."""
    s = Scenario(format_version=1)
    state, h, stream = sample_frame(s, t_s=t_s)
    scene = scene_from_state(s, state, h, stream)
    rig = Rig((RigCamera("cam0", Pinhole(200, 150, math.radians(70.0)), np.eye(4)),))
    pose = camera_poses(s, state, rig)[0]
    gl, mock = renderer(ctx, rig, rgb=True), MockRenderer(rig, CODEC)
    a, b = np.zeros((150, 200, 4), np.uint8), np.zeros((150, 200, 4), np.uint8)
    for rr, out in ((gl, a), (mock, b)):
        rr.set_scene(scene)
        rr.draw(0, pose)
        rr.read_depth(0, out)
    da, db = decode_depth(a, CODEC), decode_depth(b, CODEC)
    assert np.mean(np.isfinite(da) == np.isfinite(db)) >= 0.995
    both = np.isfinite(da) & np.isfinite(db)
    assert both.mean() > 0.5
    assert np.mean(np.abs(da - db)[both] <= 0.01) >= 0.99
    rgb = np.zeros((150, 200, 4), np.uint8)
    gl.read_rgb(0, rgb)
    assert rgb[..., :3].std() > 10                   # a shaded picture, not a blank
    gl.close()


def test_no_context_error_suggests_mock(monkeypatch):
    import moderngl

    from renderer_proc.gl.backend import create_gl_context

    def fail(**kw):
        raise Exception("eglGetDisplay failed")

    monkeypatch.setattr(moderngl, "create_context", fail)
    with pytest.raises(RendererUnavailable, match=r"eglGetDisplay failed.*--renderer mock"):
        create_gl_context()


def test_mesh_file_geometry_matches_box(ctx, tmp_path):
    """A mesh loaded with trimesh from an OBJ file renders like the equivalent box primitive."""
    import trimesh

    from cosim.world.scene import MeshInstance, load_mesh
    path = tmp_path / "slab.obj"
    trimesh.creation.box(extents=(2.0, 3.0, 1.0)).export(path)
    v, f = load_mesh(path)
    pose = make_transform(rot_y(0.3), (0.2, -0.1, 5.0))
    rig = Rig((RigCamera("cam0", Pinhole(80, 60, math.radians(60.0)), np.eye(4)),))
    base = box_scene(pose, (1.0, 1.5, 0.5))
    empty = Boxes(np.zeros((0, 4, 4)), np.zeros((0, 3)), np.zeros((0, 3), np.float32))
    with_mesh = Scene(empty, base.cylinders, base.heightfield, (MeshInstance("slab", v, f, pose, (1, 1, 1)),))
    r = renderer(ctx, rig)
    a, b = render(r, base), render(r, with_mesh)
    np.testing.assert_array_equal(a[..., 3], b[..., 3])
    assert (a[..., 3] == 255).sum() > 500
    np.testing.assert_allclose(decode_depth(a, CODEC), decode_depth(b, CODEC), atol=2 * CODEC.bound_m)
    r.close()


def test_lidar_beams_land_on_their_pixels(ctx):
    """End to end through the planned rig: each beam of the default pattern, mapped to its camera and nearest
    pixel (yaw of the rig, the v flip, Eq 5), reads a range that matches the exact ray cast along the beam
    itself, up to the nearest-pixel offset."""
    from cosim.world.camera import beam_directions
    from cosim.world.raycast import raycast
    from cosim.world.rig import beam_angles, beam_pixel_error, plan_rig

    s = Scenario.model_validate({"format_version": 1, "sensor": {"max_angular_error_deg": 0.3}})
    rig = plan_rig(s)
    assert len(rig) == 2
    state, h, stream = sample_frame(s)
    scene = scene_from_state(s, state, h, stream)
    poses = camera_poses(s, state, rig)
    r = renderer(ctx, rig)
    r.set_scene(scene)
    depth = []
    for k, c in enumerate(rig.cameras):
        img = np.zeros((c.intrinsics.height, c.intrinsics.width, 4), np.uint8)
        r.draw(k, poses[k])
        r.read_depth(k, img)
        depth.append(decode_depth(img, CODEC))
    r.close()
    el, az = beam_angles(s.sensor.pattern)
    dirs = beam_directions(el, az)
    _, cam = beam_pixel_error(rig, el, az)
    rng = np.full(len(dirs), np.nan)
    for k, c in enumerate(rig.cameras):
        sel = np.nonzero(cam == k)[0]
        p = dirs[sel] @ c.sensor_from_camera[:3, :3]
        uv = c.intrinsics.project(p)
        i = np.clip(np.floor(uv[:, 0]).astype(int), 0, c.intrinsics.width - 1)
        j = np.clip(np.floor(uv[:, 1]).astype(int), 0, c.intrinsics.height - 1)
        ray = c.intrinsics.ray_directions()[j, i]
        rng[sel] = depth[k][j, i] / ray[:, 2]
    world_from_sensor = poses[0] @ np.linalg.inv(rig.cameras[0].sensor_from_camera)
    exact = raycast(scene, np.broadcast_to(world_from_sensor[:3, 3], dirs.shape), dirs @ world_from_sensor[:3, :3].T)
    both = np.isfinite(rng) & np.isfinite(exact) & (exact < CODEC.max_depth_m)
    assert both.mean() > 0.5
    err = np.abs(rng - exact)[both]
    # measured: median 7 mm, p75 2 cm (the rest: grazing ground, where the 0.3 deg pixel offset costs
    # r dalpha tan(incidence)); swapping the two cameras' yaws gives a median of 5.4 m
    assert np.median(err) < 0.02
    assert np.percentile(err, 75) < 0.05


def looking_down(tilt_rad: float, position) -> np.ndarray:
    """World-from-camera pose (4, 4) of a camera at ``position`` (m) facing +x tilted ``tilt_rad`` down: camera
    X right = -y, Y up, Z forward; [right, up, forward] has det -1 (the paper's left-handed camera frame)."""
    fwd = np.array([math.cos(tilt_rad), 0.0, -math.sin(tilt_rad)])
    right = np.array([0.0, -1.0, 0.0])
    pose = np.eye(4)
    pose[:3, :3] = np.stack([right, np.cross(right, fwd), fwd], axis=1)
    pose[:3, 3] = position
    return pose


def test_rough_grain_surface_same_triangles_as_ray_caster(ctx, cpu_gl):
    """Random heights seen obliquely from above: GL and the exact cast agree to float precision almost
    everywhere (0.1 mm on a CPU rasteriser, 1 mm on a GPU's coarser hardware interpolation), which holds only if
    both split every quad along the same diagonal and clamp the edge ring."""
    rng = np.random.default_rng(11)
    h = rng.uniform(0.0, 1.5, (60, 30)).astype(np.float32)
    hf = HeightField(np.eye(4), h, 0.1, 6.0, 3.0)
    far = make_transform(np.eye(3), (0.0, 0.0, -100.0))
    scene = Scene(Boxes(far[None], np.array([[0.1, 0.1, 0.1]]), np.ones((1, 3), np.float32)),
                  Cylinders(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3), np.float32)), hf)
    cam = Pinhole(160, 120, math.radians(50.0))
    pose = looking_down(1.0, (1.0, 1.5, 4.5))     # above the cart's middle, looking down and forward
    rig = Rig((RigCamera("cam0", cam, np.eye(4)),))
    gl, mock = renderer(ctx, rig, float_depth=True), MockRenderer(rig, CODEC, float_depth=True)
    za, zb = np.zeros((120, 160), np.float32), np.zeros((120, 160), np.float32)
    for rr, z in ((gl, za), (mock, zb)):
        rr.set_scene(scene)
        rr.draw(0, pose)
        rr.read_zf(0, z)
    gl.close()
    both = np.isfinite(za) & np.isfinite(zb)
    assert both.mean() > 0.6
    err = np.abs(za - zb)[both]
    assert np.mean(err < (1e-4 if cpu_gl else 1e-3)) > 0.97
    assert np.mean(err < 0.01) > 0.99


def test_merged_flat_blocks_render_like_the_full_grid(ctx, monkeypatch):
    """Flat fill with a pile, an empty strip and a plateau: the merged draw mesh (flat blocks as a few large
    triangles, fans where they meet fine blocks) gives the same depths as every grid triangle drawn, and no
    pixel falls through a seam to the floor below (both agree with the exact cast)."""
    import functools

    from renderer_proc.gl import surface as surface_gl
    from renderer_proc.gl.hfmesh import SurfaceMesh

    s = Scenario(format_version=1)
    _, h, _ = sample_frame(s)
    h = h.copy()
    h[:7] = 0.0
    h[40:44, 5:9] = 1.7
    hf = HeightField(np.eye(4), h, 0.1, 6.0, 3.0)
    floor = make_transform(np.eye(3), (3.0, 1.5, -0.5))
    scene = Scene(Boxes(floor[None], np.array([[3.0, 1.5, 0.5]]), np.ones((1, 3), np.float32)),
                  Cylinders(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3), np.float32)), hf)
    cam = Pinhole(200, 150, math.radians(60.0))
    pose = looking_down(0.9, (0.5, 1.5, 4.0))
    rig = Rig((RigCamera("cam0", cam, np.eye(4)),))
    z = {}
    for name, block in (("merged", None), ("grid", 1)):
        if block is not None:
            monkeypatch.setattr(surface_gl, "SurfaceMesh", functools.partial(SurfaceMesh, block=block))
        r = renderer(ctx, rig, float_depth=True)
        r.set_scene(scene)
        r.draw(0, pose)
        z[name] = np.zeros((150, 200), np.float32)
        r.read_zf(0, z[name])
        if block is None:
            assert r._surface.count < 3 * (61 * 31)         # merged: fewer than half the grid's triangles drawn
        r.close()
    mock = MockRenderer(rig, CODEC, float_depth=True)
    mock.set_scene(scene)
    mock.draw(0, pose)
    z["exact"] = np.zeros((150, 200), np.float32)
    mock.read_zf(0, z["exact"])
    np.testing.assert_array_equal(np.isfinite(z["merged"]), np.isfinite(z["grid"]))
    both = np.isfinite(z["merged"])
    assert both.mean() > 0.6
    assert np.abs(z["merged"] - z["grid"])[both].max() < 1e-4
    err = np.abs(z["merged"] - z["exact"])[both & np.isfinite(z["exact"])]
    assert np.mean(err < 1e-4) > 0.99 and np.mean(err < 0.01) > 0.999


def test_cached_ground_image_matches_a_fresh_render(ctx):
    """The ground slab is drawn once per camera and copied into later frames while the camera's pose relative
    to the ground plane is unchanged (a mounted camera on a vehicle driving and turning on flat ground): a
    later frame, vehicles elsewhere and turned, equals what a fresh renderer draws for it."""
    from cosim.world.rig import plan_rig

    s0 = Scenario.model_validate({"format_version": 1, "sensor": {"max_angular_error_deg": 0.5}})
    s1 = Scenario.model_validate({"format_version": 1, "sensor": {"max_angular_error_deg": 0.5},
                                  "combine": {"heading_deg": 37.0}})
    rig = plan_rig(s0)
    cached, fresh = renderer(ctx, rig, rgb=True, float_depth=True), renderer(ctx, rig, rgb=True, float_depth=True)
    imgs, zfs, rgbs = {}, {}, {}
    for name, r, s, t_s in (("first", cached, s0, 0.0), ("cached", cached, s1, 40.0), ("fresh", fresh, s1, 40.0)):
        state, h, stream = sample_frame(s, t_s=t_s)
        r.set_scene(scene_from_state(s, state, h, stream))
        imgs[name], zfs[name], rgbs[name] = [], [], []
        for k, pose in enumerate(camera_poses(s, state, rig)):
            c = rig.cameras[k].intrinsics
            img, rgb = np.zeros((c.height, c.width, 4), np.uint8), np.zeros((c.height, c.width, 4), np.uint8)
            zf = np.zeros((c.height, c.width), np.float32)
            r.draw(k, pose)
            r.read_depth(k, img)
            r.read_rgb(k, rgb)
            r.read_zf(k, zf)
            imgs[name].append(img)
            zfs[name].append(zf)
            rgbs[name].append(rgb)
        if name == "first":
            keys = [t.ground.key for t in cached.targets]
    assert all(k is not None for k in keys)
    assert [t.ground.key for t in cached.targets] == keys      # the heading changed, the ground image did not
    for a, b in zip(imgs["cached"], imgs["fresh"]):
        np.testing.assert_array_equal(a[..., 3], b[..., 3])
        da, db = decode_depth(a, CODEC), decode_depth(b, CODEC)
        valid = np.isfinite(da)
        assert valid.mean() > 0.5
        # equal bytes but where float32 rounding of the (differently placed) slab tips B by one
        assert np.mean(np.abs(da - db)[valid] > 1e-9) < 1e-3
        assert np.abs(da - db)[valid].max() <= CODEC.beta_cm / 100.0 / 255.0 + 1e-9
    for a, b in zip(zfs["cached"], zfs["fresh"]):
        np.testing.assert_array_equal(np.isnan(a), np.isnan(b))
        np.testing.assert_allclose(a, b, rtol=1e-5)
    for a, b in zip(rgbs["cached"], rgbs["fresh"]):
        assert np.mean(np.abs(a.astype(int) - b.astype(int)) > 1) < 1e-3     # the same shading
    cached.close()
    fresh.close()


def test_ground_drawn_directly_when_its_edge_is_in_reach(ctx):
    """A ground square too small for the camera's reach has visible edges: no cached image, drawn per frame."""
    s = Scenario.model_validate({"format_version": 1, "render": {"ground_size_m": 60.0}})
    from cosim.world.rig import plan_rig

    rig = plan_rig(s)
    state, h, stream = sample_frame(s)
    r = renderer(ctx, rig)
    r.set_scene(scene_from_state(s, state, h, stream))
    r.draw(0, camera_poses(s, state, rig)[0])
    assert r.targets[0].ground.buffers is None and r.targets[0].ground.key is None
    r.close()
