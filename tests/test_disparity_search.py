"""The stereo matcher's disparity search from the depths in view (cosim.world.disparity_search): the
closed form d = f B / Z, the smallest search, and the packaged stereo heads' searches against their geometry at
the start pose."""
from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from cosim.errors import ScenarioError
from cosim.runtime.specs import DEFAULT_SPECS, load_callable
from cosim.scenario.config.cameras import SEARCH_EDGE_PX, StereoCamera
from cosim.scenario.config.machines import Auger
from cosim.scenario.loader import load_scenario, resolve_scenario_arg
from cosim.world.disparity_search import (
    auger_top_m,
    disparity_of_depth,
    disparity_search,
    searched_depths_m,
    spout_view_depths_m,
)
from cosim.world.geometry import entity_pose
from cosim.world.sensors import world_from_sensor

ROOT = Path(__file__).resolve().parents[1]
#: every packaged scenario and example with a stereo camera
STEREO_FILES = ("stereo_spout", "lidar_and_stereo", *sorted(str(p) for p in (ROOT / "examples" / "camera_variants").glob("*.yaml")))


def test_the_disparity_is_f_b_over_z():
    assert disparity_of_depth(2.0, 500.0, 0.2) == pytest.approx(50.0, rel=1e-15)
    assert disparity_of_depth(4.0, 500.0, 0.2) == pytest.approx(25.0, rel=1e-15)


def test_the_spout_heads_search_by_hand():
    """S21B at half width (f = 512 / tan(47.7 deg) px, B = 0.21 m) 6.0 m above the ground; the auger's top at the
    spout 3.8 + 6 sin(8 deg) + 0.2 = 4.835 m, nearer than the rim top (3.06 m) + 0.5 m: near 1.165 m (d = 83.98
    px), far 6.5 m (d = 15.05 px); with the 1 px edge 14 .. 85 px, 72 px, so 80. Without the tube: 2.44 m, 32."""
    f = 512.0 / math.tan(math.radians(95.4 / 2.0))
    top = auger_top_m(Auger())
    assert top == pytest.approx(3.8 + 6.0 * math.sin(math.radians(8.0)) + 0.2, rel=1e-12)
    near, far = spout_view_depths_m(6.0, 3.06, top)
    assert (near, far) == pytest.approx((1.16496, 6.5), abs=1e-5)
    assert f * 0.21 / near == pytest.approx(83.98, abs=0.01) and f * 0.21 / far == pytest.approx(15.05, abs=0.01)
    assert disparity_search(f, 0.21, near, far) == (14, 80)
    assert spout_view_depths_m(6.0, 3.06, 6.5) == pytest.approx((2.44, 6.5), abs=1e-12), "a tube above the camera"
    assert disparity_search(f, 0.21, 2.44, 6.5) == (14, 32)


@pytest.mark.parametrize("focal_px, baseline_m", [(465.9, 0.21), (441.25, 0.075), (931.98, 0.21), (300.0, 0.5)])
@pytest.mark.parametrize("near, far", [(0.9, 1.2), (2.44, 6.5), (3.94, 8.0), (1.0, 30.0), (5.0, 5.5)])
def test_the_search_is_the_smallest_holding_every_depth_inside_its_edge(focal_px, baseline_m, near, far):
    lo, num = disparity_search(focal_px, baseline_m, near, far)
    d_far, d_near = focal_px * baseline_m / far, focal_px * baseline_m / near   # d = f B / Z
    e = SEARCH_EDGE_PX
    assert num % 16 == 0 and lo >= 0
    assert lo + e <= d_far and d_near <= lo + num - 1 - e, "both ends at least the edge inside"
    assert lo + 1 + e > d_far or lo + 1 + num - 1 - e < d_near, "a larger minimum would lose a depth"
    assert num == 16 or lo + num - 16 - 1 - e < d_near, "16 fewer disparities would lose the near end"
    z_near, z_far = searched_depths_m(focal_px, baseline_m, lo, num)
    assert z_near <= near * (1 + 1e-12) and z_far >= far * (1 - 1e-12)
    d = np.linspace(d_far, d_near, 101)
    assert np.all((d >= lo + e) & (d <= lo + num - 1 - e))


def test_the_whole_search_ends_at_the_edge_from_zero_and_bad_depths_are_refused():
    assert searched_depths_m(465.9, 0.21, 0, 128) == pytest.approx((465.9 * 0.21 / 126.0, 465.9 * 0.21 / 1.0),
                                                                   rel=1e-12)
    with pytest.raises(ValueError, match="0 < z_near_m < z_far_m"):
        disparity_search(465.9, 0.21, 3.0, 2.0)
    with pytest.raises(ValueError, match="within 1.0 px of 0"):
        disparity_search(441.25, 0.075, 1.0, 40.0)                  # f B / 40 m = 0.83 px


def _cart_depths(s, cam) -> np.ndarray:
    """Planar depths (8,), m, of the cart interior's corners at the floor and at the rim top in ``cam``'s frame
    at the start pose."""
    state = load_callable(DEFAULT_SPECS["dynamics"].initial_state)(s)[0]
    c = s.cart
    corners = np.array([[x, y, z, 1.0] for z in (c.floor_height_m, c.rim_top_m)
                        for x in (-c.interior_length_m / 2, c.interior_length_m / 2)
                        for y in (-c.interior_width_m / 2, c.interior_width_m / 2)])
    cam_from_world = np.linalg.inv(world_from_sensor(cam, state))
    return (cam_from_world @ entity_pose(state, "cart") @ corners.T)[2]


@pytest.mark.parametrize("name", STEREO_FILES, ids=lambda n: Path(n).stem)
def test_every_stereo_heads_search_holds_the_cart_and_a_spout_heads_is_derived(name):
    """Each packaged stereo head's search holds the cart's whole depth span at the start pose; a head looking
    straight down (pitch 90 deg) with a cut search has exactly the one its height derives (a variant that
    inherits a search from its base and moves the head would fail here)."""
    s = load_scenario(resolve_scenario_arg(name))
    for cam in (c for c in s.cameras.values() if isinstance(c, StereoCamera)):
        z = _cart_depths(s, cam)
        z_near, z_far = searched_depths_m(cam.focal_px, cam.baseline_m, cam.min_disparity_px, cam.num_disparities)
        assert z_near < z.min() and z.max() < z_far, (name, z, z_near, z_far)
        if cam.mount.rpy_deg[1] == 90.0 and (cam.min_disparity_px, cam.num_disparities) != (0, 128):
            near, far = spout_view_depths_m(cam.mount.xyz_m[2], s.cart.rim_top_m, auger_top_m(s.auger))
            assert (cam.min_disparity_px, cam.num_disparities) == disparity_search(cam.focal_px, cam.baseline_m,
                                                                                   near, far), name


SPOUT = resolve_scenario_arg("stereo_spout")
LOWER = "sensors.spout.mount.xyz_m=[-2.0, 7.45, 5.5]"


def test_a_head_moved_nearer_the_auger_with_its_old_search_is_refused_naming_the_search_that_holds_it():
    """stereo_spout's head 0.5 m lower keeps the search cut for 6.0 m (14-93 px: 1.06-6.52 m); the auger tube's
    top at the spout is then 5.5 - 4.835 = 0.665 m below it, nearer than the search holds (its pixels would be
    matched inside the cart): refused at the search's key, naming the tube and a search holding the tube to the
    ground, which is valid."""
    with pytest.raises(ScenarioError, match=r"sensors.spout.num_disparities: camera 'spout': its disparity search "
                                            r"\(14-93 px: min_disparity_px 14, num_disparities 80\) holds planar "
                                            r"depths 1.06-6.52 m, but at the start the auger over the cart at "
                                            r"0.6\d m is nearer") as info:
        load_scenario(SPOUT, [LOWER])
    text = str(info.value)
    m, n = (int(x) for x in re.search(r"holds [\d.-]+ m: min_disparity_px (\d+), num_disparities (\d+)", text).groups())
    near, far = (float(x) for x in re.search(r"the search that holds ([\d.]+)-([\d.]+) m", text).groups())
    assert near == pytest.approx(5.5 - auger_top_m(Auger()), abs=0.02) and far == pytest.approx(5.5, abs=0.01)
    cam = load_scenario(SPOUT, check_world=False).sensors["spout"]
    z_near, z_far = searched_depths_m(cam.focal_px, cam.baseline_m, m, n)
    assert z_near < near and far < z_far and n % 16 == 0
    load_scenario(SPOUT, [LOWER, f"sensors.spout.min_disparity_px={m}", f"sensors.spout.num_disparities={n}"])


def test_a_smaller_head_with_the_wide_heads_search_is_refused_and_told_its_derived_search():
    """The OAK-D module (f B = 33.1 px m) in lidar_and_stereo's head keeps the S21B's search, which holds 0.36-2.21
    m: the grain at 4 m is farther. The search the message gives is the one the spout geometry derives for the
    OAK-D (examples/camera_variants/stereo_spout_oak_d.yaml: 4, 32)."""
    sets = ["sensors.spout.profile=oak_d"]
    with pytest.raises(ScenarioError, match=r"holds planar depths 0.36-2.21 m, but at the start the grain in the "
                                            r"cart at 4.00 m is farther.*min_disparity_px 4, num_disparities 32"):
        load_scenario(resolve_scenario_arg("lidar_and_stereo"), sets)
    oak = load_scenario(resolve_scenario_arg("examples/camera_variants/stereo_spout_oak_d.yaml"), check_world=False)
    assert (oak.sensors["spout"].min_disparity_px, oak.sensors["spout"].num_disparities) == (4, 32)
    load_scenario(resolve_scenario_arg("lidar_and_stereo"),
                  sets + ["sensors.spout.min_disparity_px=4", "sensors.spout.num_disparities=32"])
