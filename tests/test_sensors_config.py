"""Named sensors (``sensors:``): records, profiles, the ``sensor:`` shorthand, validation at file:line, the
per-sensor plausibility checks and the blocks each sensor gets (docs/cameras.md)."""
from __future__ import annotations

import pytest

from cosim.errors import ScenarioError
from cosim.runtime.specs import build_schema, ring_specs
from cosim.scenario.config import Scenario
from cosim.scenario.config.cameras import DepthCamera, LidarSensor, StereoCamera
from cosim.scenario.config.profiles import SOURCES, load_profile, profile_names
from cosim.scenario.loader import dump_resolved, load_scenario, load_scenario_text, resolve_scenario_arg

MOUNT = "{parent: combine, xyz_m: [-2.0, 7.6, 5.6], rpy_deg: [0.0, 90.0, 90.0]}"


def text(sensors: str, extra: str = "") -> str:
    return f"format_version: 1\n{extra}sensors:\n{sensors}"


def test_the_shorthand_is_one_lidar_named_lidar_with_every_legacy_block():
    s = load_scenario(resolve_scenario_arg("default"))
    assert list(s.sensor_set) == ["lidar"] and s.lidar is s.sensor and s.lidar_name == "lidar"
    assert isinstance(s.sensor_set["lidar"], LidarSensor) and s.cameras == {} and s.depth_sensors == ("lidar",)
    names = {b.name for b in build_schema(s, ring_specs(s)).blocks}
    assert {"beams_depth", "lidar_points", "perc_state", "heightmap_perceived"} <= set(names)
    assert not [n for n in names if n.startswith(("cam_", "sensor_"))], "the shorthand adds no block"


def test_profiles_name_a_source_and_a_reference_for_every_value():
    assert {"oak_d", "multisense_s21b", "kinect_class_structured_light", "kinect_v1_structured_light",
            "azure_kinect_nfov", "azure_kinect_nfov_binned"} <= set(profile_names())
    kinds = {load_profile(n).kind for n in profile_names()}
    assert {"stereo_camera", "depth_camera"} <= kinds
    for name in profile_names():
        for key, v in load_profile(name).values.items():
            assert v.source in SOURCES and len(v.ref) > 10, (name, key)


def test_a_profile_fills_what_the_camera_leaves_out_and_the_dump_round_trips():
    s = load_scenario_text(text(f"  front:\n    kind: stereo_camera\n    profile: oak_d\n    baseline_m: 0.1\n"
                                f"    mount: {MOUNT}\n"))
    cam = s.cameras["front"]
    assert isinstance(cam, StereoCamera)
    assert (cam.width_px, cam.height_px, cam.hfov_deg, cam.num_disparities) == (640, 400, 71.9, 96)
    assert cam.baseline_m == 0.1, "a value set in the scenario wins over the profile"
    assert cam.focal_px == pytest.approx(441.25, abs=0.01), "the Luxonis documentation's 441.25 px at 400P"
    again = load_scenario_text(dump_resolved(s))
    assert again == s and hash(again) == hash(s)


def test_a_lidar_under_sensors_is_the_lidar_and_sensor_stays_default():
    s = load_scenario_text(text(f"  mast:\n    kind: lidar\n    method: beam_native\n  tof:\n    kind: depth_camera\n"
                                f"    mount: {MOUNT}\n"))
    assert s.lidar_name == "mast" and s.lidar.method == "beam_native" and s.depth_sensors == ("mast", "tof")
    assert isinstance(s.cameras["tof"], DepthCamera) and list(s.cameras) == ["tof"]


@pytest.mark.parametrize("sensors, extra, where, match", [
    ("  a:\n    kind: lidar\n  b:\n    kind: lidar\n", "", "sensors", "2 LiDARs"),
    ("  a:\n    kind: lidar\n", "sensor:\n  range_max_m: 30.0\n", "sensors", "both sensor: and sensors:"),
    (f"  s:\n    kind: stereo_camera\n    mount: {MOUNT}\n", "renderer: mock\n", "sensors",
     "needs the GL renderer.*no texture to match"),
    (f"  s:\n    kind: stereo_camera\n    block_size: 4\n    mount: {MOUNT}\n", "", "sensors.s", "must be odd"),
    (f"  s:\n    kind: stereo_camera\n    num_disparities: 40\n    mount: {MOUNT}\n", "", "sensors.s",
     "multiple of 16"),
    (f"  s:\n    kind: depth_camera\n    profile: oak_d\n    mount: {MOUNT}\n", "", "sensors.s",
     "profile 'oak_d' describes a stereo_camera"),
    (f"  s:\n    kind: depth_camera\n    profile: nope\n    mount: {MOUNT}\n", "", "sensors.s",
     "no sensor profile 'nope'"),
    (f"  s:\n    kind: depth_camera\n    hfov: 60\n    mount: {MOUNT}\n", "", "sensors.s.hfov", "unknown key"),
    ("  s:\n    kind: depth_camera\n", "", "sensors.s.mount", "missing required key 'mount'"),
    (f"  s:\n    kind: sonar\n    mount: {MOUNT}\n", "", "sensors.s", "kind"),
    (f"  S-1:\n    kind: rgb_camera\n    mount: {MOUNT}\n", "", "sensors.S-1.[key]", "should match pattern"),
])
def test_bad_sensors_are_reported_at_their_key(sensors, extra, where, match):
    with pytest.raises(ScenarioError, match=match) as info:
        load_scenario_text(text(sensors, extra), check_world=False)
    assert any(p.path == where for p in info.value.problems), [str(p) for p in info.value.problems]


def test_set_reaches_keys_inside_a_named_sensor():
    base = text(f"  tof:\n    kind: depth_camera\n    mount: {MOUNT}\n")
    s = load_scenario_text(base, overrides=["sensors.tof.hfov_deg=70", "sensors.tof.mount.xyz_m=[-2, 7.5, 5.5]"],
                           check_world=False)
    assert s.cameras["tof"].hfov_deg == 70.0 and s.cameras["tof"].mount.xyz_m == (-2.0, 7.5, 5.5)
    with pytest.raises(ScenarioError, match="<--set>:1:.*sensors.tof.hfov_deg: Input should be greater than 1"):
        load_scenario_text(base, overrides=["sensors.tof.hfov_deg=0.5"], check_world=False)


@pytest.mark.parametrize("mount, match", [
    ("{parent: combine, xyz_m: [-2.0, 7.6, -0.5], rpy_deg: [0.0, 90.0, 90.0]}", "camera 'tof' is 0.50 m below"),
    ("{parent: combine, xyz_m: [0.0, 0.0, 2.0], rpy_deg: [0.0, 90.0, 90.0]}", "camera 'tof' is inside the combine"),
    ("{parent: combine, xyz_m: [-2.0, 7.6, 5.6], rpy_deg: [0.0, -60.0, 90.0]}",
     "the cart is never in camera 'tof''s field of view"),
])
def test_each_camera_is_checked_like_the_lidar(mount, match):
    with pytest.raises(ScenarioError, match=match) as info:
        load_scenario_text(text(f"  tof:\n    kind: depth_camera\n    mount: {mount}\n"), check_world=True)
    assert info.value.problems[0].path.startswith("sensors.tof.mount")


def test_each_eye_of_a_stereo_pair_is_checked():
    """The left eye is clear of the combine's body; the right one, 1.5 m to its right (looking forward: towards
    the combine's centre line), is inside it."""
    mount = "{parent: combine, xyz_m: [-3.0, 2.5, 2.0], rpy_deg: [0.0, 0.0, 0.0]}"
    with pytest.raises(ScenarioError, match=r"camera 'st' \(right\) is inside the combine"):
        load_scenario_text(text(f"  st:\n    kind: stereo_camera\n    baseline_m: 1.5\n    mount: {mount}\n"),
                           check_world=True)


def test_only_the_parts_a_camera_needs_get_blocks():
    s = load_scenario_text(text(
        f"  st:\n    kind: stereo_camera\n    mount: {MOUNT}\n"
        f"  tof:\n    kind: depth_camera\n    labels: true\n    mount: {MOUNT}\n"
        f"  eye:\n    kind: rgb_camera\n    mount: {MOUNT}\n"))
    names = set({b.name for b in build_schema(s, ring_specs(s)).blocks})
    assert {"cam_st_rgb", "cam_st_right", "cam_st_measured", "cam_st_points", "sensor_st"} <= names
    assert {"cam_tof_depth", "cam_tof_labels", "cam_tof_measured", "cam_tof_points", "sensor_tof"} <= names
    assert {"cam_eye_rgb"} <= names
    assert not {"cam_st_depth", "cam_st_labels", "cam_tof_rgb", "cam_eye_depth", "cam_eye_measured",
                "sensor_eye", "lidar_points", "beams_depth"} & names, "nothing that no one reads"


def test_the_mock_scales_colour_cameras_keeps_depth_cameras_whole_and_keeps_the_field_of_view():
    from cosim.world.sensors import camera_pinhole, points_stride

    s = load_scenario_text(text(f"  rgb:\n    kind: rgb_camera\n    mount: {MOUNT}\n"
                                f"  tof:\n    kind: depth_camera\n    points_stride: 3\n    mount: {MOUNT}\n",
                                "renderer: mock\n"))
    pin = camera_pinhole(s.cameras["rgb"], s)
    assert (pin.width, pin.height) == (160, 120) and pin.hfov_rad == pytest.approx(1.0471975511965976)
    # a depth camera's error model is per pixel of the device: its own size and stride under the mock too
    tof = camera_pinhole(s.cameras["tof"], s)
    assert (tof.width, tof.height, points_stride(s.cameras["tof"], s)) == (640, 480, 3)
    gl = Scenario.model_validate_json(s.model_copy(update={"renderer": "gl"}).model_dump_json())
    assert (camera_pinhole(gl.cameras["rgb"], gl).width, camera_pinhole(gl.cameras["rgb"], gl).height) == (640, 480)


def test_compare_sets_the_method_of_a_named_lidar_and_keeps_cameras():
    """launch.py compare's paper-style run uses the camera rig: on the LiDAR of sensors: too; a camera-only
    scenario keeps its cameras; a stereo scenario given no renderer compares under GL (the mock has no texture)."""
    from cosim.studies.compare import variants

    s = load_scenario_text(text(f"  mast:\n    kind: lidar\n    method: beam_native\n  spout:\n    kind: "
                                f"stereo_camera\n    mount: {MOUNT}\n", "renderer: none\nfeedback: ground_truth\n"))
    v = variants(s)
    assert v["perception_paper"].lidar.method == "camera_rig" and v["perception_fused"].lidar.method == "beam_native"
    assert v["perception_paper"].sensor == s.sensor and set(v["perception_paper"].sensors) == {"mast", "spout"}
    assert {x.renderer for x in v.values()} == {"gl"}
