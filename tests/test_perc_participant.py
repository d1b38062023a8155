"""The perception participant over an in-process segment, its summary and the accuracy report."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as hst

from cosim.errors import FrameMismatch
from cosim.scenario.config import Scenario
from cosim.testing.synthetic import encode_linear, stitched_rig
from cosim.world.fastcast import embree_available
from cosim.world.geometry import vehicle_pose
from cosim.world.raycast import raycast
from cosim.world.scene import scene_from_state
from dynamics_proc.blocks import declare_blocks as dynamics_blocks
from perception_proc.accuracy.report import render_markdown, write_report
from perception_proc.blocks import declare_blocks
from perception_proc.orderstats import median_sorted, percentile_sorted, percentiles
from perception_proc.participant import PerceptionParticipant, create
from perception_proc.summary import summarize
from shm_schema import Schema, Segment, image_block

SCENARIO = Scenario.model_validate_json(json.dumps({
    "format_version": 1, "renderer": "mock", "seed": 11,
    "sensor": {"mount": {"parent": "combine", "xyz_m": [-2.0, 3.0, 8.0], "rpy_deg": [0.0, 55.0, 90.0]},
               "pattern": {"preset": "grid", "elevation_min_deg": -40.0, "elevation_max_deg": 30.0,
                           "azimuth_min_deg": -55.0, "azimuth_max_deg": 55.0, "elevation_count": 56,
                           "azimuth_count": 88}},
    "perception": {"accuracy_every_frames": 1},
}))
RIG = stitched_rig(2, 200, 200, 70.0, yaw_step_deg=60.0, pitch_deg=-5.0)


def _state(segment_view, t=0.3):
    s = {f: 0.0 for f in segment_view.as_dict()}
    s.update(t_s=t, combine_x_m=0.0, combine_y_m=0.0, combine_yaw_rad=0.0, cart_x_m=-2.0, cart_y_m=7.4,
             cart_yaw_rad=0.03, tractor_x_m=20.0, tractor_y_m=7.4, spout_x_m=-2.3, spout_y_m=7.4, spout_z_m=4.8,
             stream_points=0, impact_valid=0)
    return s


def _segment():
    blocks = dynamics_blocks(SCENARIO) + [image_block(f"{c.name}_depth", "renderer", c.intrinsics.height,
                                                      c.intrinsics.width) for c in RIG.cameras]
    blocks += declare_blocks(SCENARIO)
    return Segment.local(Schema(blocks, ("dynamics", "renderer", "perception")))


def _step(part, frame):
    """Step ``part`` through frame ``frame`` and publish its outputs (the overlapped rest and flush included)."""
    rest = part.step(frame)
    if rest is not None:
        rest()
    part.flush()


def _publish(seg, frame, part):
    """Dynamics and renderer stand-ins: a heaped cart, rendered exactly and encoded (Eqs 1-2)."""
    with seg.write("dyn_state", frame) as st:
        state = _state(st)
        st.update(state)
    with seg.write("heightmap_truth", frame) as h:
        nx, ny = h.shape
        gx, gy = np.meshgrid((np.arange(nx) + 0.5) * 0.1, (np.arange(ny) + 0.5) * 0.1, indexing="ij")
        h[...] = np.maximum(0.8, 1.7 - 0.42 * np.hypot(gx - 3.0, gy - 1.5))
    with seg.write("stream", frame) as s:
        s[...] = 0.0
    scene = scene_from_state(SCENARIO, state, np.array(seg.view("heightmap_truth")), np.array(seg.view("stream")))
    wfs = vehicle_pose(0.0, 0.0, 0.0) @ part.pipeline.level_from_sensor if part.pipeline is not None else None
    for cam in RIG.cameras:
        wfc = wfs @ cam.sensor_from_camera
        rays = cam.intrinsics.ray_directions()
        d = rays.reshape(-1, 3) @ wfc[:3, :3].T
        t = raycast(scene, np.broadcast_to(wfc[:3, 3], d.shape), d).reshape(rays.shape[:2])
        with seg.write(f"{cam.name}_depth", frame) as img:
            img[...] = encode_linear(np.where(np.isfinite(t), t * rays[..., 2], np.nan), SCENARIO.sensor.codec)


@pytest.fixture(scope="module")
def stepped():
    seg = _segment()
    part = PerceptionParticipant(SCENARIO, rig=RIG)
    part.start(seg)
    _publish(seg, 1, part)
    _step(part, 1)
    return seg, part


def test_outputs_are_written_with_the_frame(stepped):
    seg, part = stepped
    for b in ("perc_state", "heightmap_perceived", "lidar_points"):
        assert seg.frame_of(b) == 1
    st = seg.view("perc_state")
    assert st.frame == 1 and st.t_s == pytest.approx(0.3)
    assert st.cart_valid == 1
    pts = seg.view("lidar_points")
    valid = np.isfinite(pts[:, 3])
    assert valid.sum() == st.valid_beams > 0.5 * len(pts)
    np.testing.assert_allclose(np.linalg.norm(pts[valid, :3], axis=1), pts[valid, 3], rtol=1e-5)
    assert np.isnan(pts[~valid]).all()
    assert st.cart_yaw_rad == pytest.approx(0.03, abs=0.01)


def test_accuracy_fields_against_the_exact_cast(stepped):
    st = stepped[0].view("perc_state")
    assert st.acc_evaluated == 1
    assert st.range_err_median_m < 2e-3
    assert st.frac_above_5cm < 0.02
    assert st.corner_error_m < 0.05
    assert st.heightmap_rmse_m < 0.03
    assert math.isnan(st.impact_error_m)                 # no stream in this scene: nothing to compare
    assert st.impact_valid == 0


@settings(max_examples=200, deadline=None)
@given(hst.lists(hst.floats(0.0, 50.0), min_size=1, max_size=400), hst.integers(0, 3))
def test_order_statistics_are_numpys_bit_for_bit(values, decimals):
    """perception_proc.orderstats gives the same bytes as np.median and np.percentile (ties included: rounded
    values repeat)."""
    e = np.round(np.asarray(values), decimals)
    s = np.sort(e)
    for q in (0.5, 90.0, 99.0, 99.5):
        assert np.float64(percentile_sorted(s, q)).tobytes() == np.float64(np.percentile(e, q)).tobytes()
    assert np.float64(median_sorted(s)).tobytes() == np.float64(np.median(e)).tobytes()
    assert percentiles(e, (0.5, 99.5)).tobytes() == np.percentile(e, (0.5, 99.5)).tobytes()
    assert math.isnan(median_sorted(s[:0])) and math.isnan(percentile_sorted(s[:0], 99.0))


def test_perceived_heights_match_truth(stepped):
    seg, _ = stepped
    h, t = np.array(seg.view("heightmap_perceived")), np.array(seg.view("heightmap_truth"))
    ok = np.isfinite(h)
    assert ok.mean() > 0.1
    err = np.abs(h[ok] - t[ok])
    assert np.median(err) < 0.01
    assert np.mean(err < 0.03) > 0.95
    assert err.max() < 0.08                             # cell statistic vs the cell-centre truth on a cone


def test_frame_mismatch_is_refused(stepped):
    seg, part = stepped
    with pytest.raises(FrameMismatch, match="expected cam0_depth of frame 2, found frame 1"):
        part.step(2)


def test_noise_is_reproducible_per_seed_and_frame():
    noisy = SCENARIO.model_copy(update={"sensor": SCENARIO.sensor.model_copy(update={
        "noise": SCENARIO.sensor.noise.model_copy(update={"range_sigma_m": 0.01, "dropout": 0.1})})})
    seg = _segment()
    runs = []
    for _ in range(2):
        part = PerceptionParticipant(noisy, rig=RIG)
        part.start(seg)
        _publish(seg, 3, part)
        _step(part, 3)
        runs.append(np.array(seg.view("lidar_points")))
    np.testing.assert_array_equal(runs[0], runs[1])
    clean = part.pipeline.resample([seg.view(f"{c.name}_depth") for c in RIG.cameras])
    other = part.pipeline.noisy(clean.copy(), 4)
    assert not np.array_equal(np.isnan(other), np.isnan(runs[0][:, 3]))
    drop = np.isnan(runs[0][:, 3]) & np.isfinite(clean)
    assert 0.05 < drop.sum() / np.isfinite(clean).sum() < 0.15


def test_summary_and_report(stepped, tmp_path):
    seg, _ = stepped
    st = seg.view("perc_state").as_dict()
    series = {f"perc_state.{k}": np.array([v, v], dtype=np.float64) for k, v in st.items()}
    out = summarize(SCENARIO, series, np.array(seg.view("heightmap_truth")), np.array(seg.view("heightmap_perceived")))
    p = out["perception"]
    for key in ("heightmap_rmse_m", "coverage", "corner_error_m", "impact_error_m", "range_error"):
        assert key in p
    assert p["impact_error_m"] is None
    assert p["range_error"]["mean_m"] == pytest.approx(st["range_err_mean_m"])
    assert p["range_error"]["beams"] == 2 * st["range_beams"]
    assert p["range_error"]["ray_caster"] == ("embree" if embree_available() else "numpy")
    off = SCENARIO.model_copy(update={"perception": SCENARIO.perception.model_copy(update={"accuracy_every_frames": 0})})
    assert summarize(off, series, None, None)["perception"]["range_error"]["ray_caster"] is None
    assert 0 < p["coverage"] <= 1
    json.dumps(out, allow_nan=False)
    md, js = write_report(p, tmp_path)
    text = md.read_text()
    assert "| 2-5 |" in text and "Working range 2-15 m" in text
    assert json.loads(js.read_text())["range_error"]["bands"][1]["lo_m"] == 2.0
    assert "NOT met" in render_markdown({"range_error": {"working_mean_m": 0.02, "working_frac_above_5cm": 0.0}})


def test_create_and_missing_blocks():
    part = create(SCENARIO)
    assert part.name == "perception"
    seg = Segment.local(Schema(declare_blocks(SCENARIO), ("perception",)))
    with pytest.raises(KeyError, match="_depth"):
        part.start(seg)


@pytest.mark.slow
def test_full_ring_with_the_mock_renderer():
    from cosim.runtime.inprocess import simulate

    sc = Scenario.model_validate_json(json.dumps({
        "format_version": 1, "renderer": "mock", "render": {"mock_scale": 0.5},
        "sensor": {"pattern": {"preset": "grid", "azimuth_count": 120, "elevation_count": 80}},
        "perception": {"accuracy_every_frames": 1}}))
    run = simulate(sc, frames=2)
    s = run.recorder.series()
    assert s["perc_state.frame"].tolist() == [0.0, 1.0, 2.0]
    valid = s["perc_state.cart_valid"] == 1                # a sparse pattern may rightly give no answer
    assert np.all(s["perc_state.corner_error_m"][valid] < 0.1)
    assert np.all(np.isnan(s["perc_state.corner_error_m"][~valid]))
    assert np.all(s["perc_state.range_err_median_m"] < 2e-3)
    assert np.all(s["perc_state.frac_above_5cm_2_15"] < 0.02)
    out = summarize(sc, {k: v for k, v in s.items() if k.startswith("perc_state.")},
                    run.segment.view("heightmap_truth"), run.segment.view("heightmap_perceived"))
    assert out["perception"]["range_error"]["frames_evaluated"] == 3


def test_accuracy_off_never_casts_and_the_summary_says_so(monkeypatch):
    """perception.accuracy_every_frames: 0 keeps the exact ray cast off the frame (never called), the frame's
    accuracy fields NaN, and the summary's range_error says evaluation was off, with null statistics; with
    evaluation on it says how often."""
    import perception_proc.accuracy.stage as acc_mod

    off = SCENARIO.model_copy(update={"perception": SCENARIO.perception.model_copy(
        update={"accuracy_every_frames": 0})})

    def no_cast(*_a, **_k):
        raise AssertionError("the exact ray cast ran with evaluation off")

    monkeypatch.setattr(acc_mod, "exact_ranges", no_cast)
    seg = _segment()
    part = PerceptionParticipant(off, rig=RIG)
    part.start(seg)
    _publish(seg, 0, part)
    _step(part, 0)
    st = seg.view("perc_state").as_dict()
    assert st["acc_evaluated"] == 0 and math.isnan(st["range_err_mean_m"]) and st["cart_valid"] == 1
    series = {f"perc_state.{k}": np.array([v], dtype=np.float64) for k, v in st.items()}
    p = summarize(off, series, None, np.array(seg.view("heightmap_perceived")))["perception"]
    re = p["range_error"]
    assert re["evaluation"].startswith("off (perception.accuracy_every_frames: 0)")
    assert re["frames_evaluated"] == 0 and re["mean_m"] is None and re["working_p99_m"] is None
    assert "accuracy evaluation: off" in render_markdown(p)
    on = summarize(SCENARIO, series, None, None)["perception"]["range_error"]["evaluation"]
    assert on == f"every 1 frame, {SCENARIO.perception.accuracy_beams} sampled beams each"
