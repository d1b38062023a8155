"""Stand-in participants for the viewer and recording tests, and checks of the stand-ins themselves.

They write what the real participants publish (docs/CONTRACTS.md), deterministically from the frame number:
``dyn_state`` (time, vehicle poses, the Fig 9 auger signals, section fullness), ``heightmap_truth``; the
renderer's ``cam0_depth`` and, with a viewer, ``cam0_rgb``; perception's ``perc_state``, ``heightmap_perceived``
(with unknown cells) and ``lidar_points`` (with invalid beams). ``pace_s`` makes each step take that long, like a
real participant's compute (so a run lasts long enough to attach to it mid-way); ``kill_at`` SIGKILLs itself.
"""
from __future__ import annotations

import os
import signal
import time

import numpy as np

from cosim.runtime.inprocess import simulate
from cosim.runtime.specs import ParticipantSpec
from cosim.scenario.config import Scenario
from shm_schema import ArrayBlock, Field, StructBlock, image_block

IMG_H, IMG_W = 48, 64
NX, NY = 60, 30
NXC, NYC = 30, 15
N_BEAMS = 400
SECTIONS = 9
VEHICLES = ("combine", "tractor", "cart")


def blocks_dynamics(scenario):
    fields = [Field("t_s", "s"), Field("frame", "", "i8")]
    for v in VEHICLES:
        fields += [Field(f"{v}_x_m", "m"), Field(f"{v}_y_m", "m"), Field(f"{v}_yaw_rad", "rad")]
    fields += [Field("desired_auger_x_m", "m"), Field("actual_auger_x_m", "m"), Field("spilled_m3", "m^3")]
    fields += [Field(f"section{k}_fullness") for k in range(1, SECTIONS + 1)]
    return [StructBlock("dyn_state", "dynamics", tuple(fields)),
            ArrayBlock("heightmap_truth", "dynamics", "f4", (NX, NY), unit="m")]


def blocks_renderer(scenario):
    out = [StructBlock("render_state", "renderer", (Field("t_s", "s"), Field("valid_fraction"))),
           image_block("cam0_depth", "renderer", IMG_H, IMG_W)]
    if scenario.viewer:
        out.append(image_block("cam0_rgb", "renderer", IMG_H, IMG_W))
    return out


def blocks_perception(scenario):
    return [StructBlock("perc_state", "perception", (Field("t_s", "s"), Field("coverage"), Field("cart_valid", "",
                                                                                                   "i8"))),
            ArrayBlock("heightmap_perceived", "perception", "f4", (NXC, NYC), unit="m"),
            ArrayBlock("lidar_points", "perception", "f4", (N_BEAMS, 4), unit="m")]


def truth(frame: int) -> np.ndarray:
    """(NX, NY) float32 mound that grows with the frame, m."""
    i, j = np.meshgrid(np.arange(NX), np.arange(NY), indexing="ij")
    peak = 0.02 * frame
    return np.maximum(0.0, peak - 0.01 * np.hypot(i - NX / 3, j - NY / 2)).astype(np.float32)


def valid_beams(frame: int) -> np.ndarray:
    """(N_BEAMS,) bool: which beams return a point at ``frame`` (some rotate out)."""
    return (np.arange(N_BEAMS) + frame) % 7 != 0


def points(frame: int) -> np.ndarray:
    """(N_BEAMS, 4) float32 lidar_points (sensor frame, camera axes): a tilted plane, NaN rows invalid."""
    k = np.arange(N_BEAMS)
    x = (k % 20 - 10) * 0.3
    z = 4.0 + (k // 20) * 0.3 + 0.01 * frame
    y = -1.0 - 0.2 * z
    p = np.stack([x, y, z, np.sqrt(x * x + y * y + z * z)], axis=1).astype(np.float32)
    p[~valid_beams(frame)] = np.nan
    return p


class StandIn:
    """One role of the stand-in ring."""

    def __init__(self, scenario, role, pace_s=0.0, kill_at=-1):
        self.name, self.scenario, self.pace_s, self.kill_at = role, scenario, pace_s, kill_at
        self.seg = None

    def start(self, segment):
        self.seg = segment

    def step(self, frame):
        if frame == self.kill_at:
            os.kill(os.getpid(), signal.SIGKILL)
        if self.pace_s:
            time.sleep(self.pace_s)  # stands for the compute time of a real participant, not synchronisation
        seg, t = self.seg, frame * self.scenario.timing.sensor_period_s
        if self.name == "dynamics":
            with seg.write("dyn_state", frame) as v:
                v.t_s, v.frame = t, frame
                for n, vname in enumerate(VEHICLES):
                    setattr(v, f"{vname}_x_m", 2.0 * t - 3.0 * n)
                    setattr(v, f"{vname}_y_m", 7.0 * (n > 0))
                    setattr(v, f"{vname}_yaw_rad", 0.01 * n)
                v.desired_auger_x_m = 1.0 + 0.5 * (frame // 20)
                v.actual_auger_x_m = 1.0 + 0.5 * (frame // 20) - 0.2 * np.exp(-(frame % 20) / 5)
                v.spilled_m3 = float("nan") if frame == 0 else 0.0
                for k in range(1, SECTIONS + 1):
                    setattr(v, f"section{k}_fullness", min(1.2, 0.01 * frame * (SECTIONS + 1 - k) / SECTIONS))
            with seg.write("heightmap_truth", frame) as h:
                h[...] = truth(frame)
        elif self.name == "renderer":
            with seg.write("cam0_depth", frame) as img:
                img[..., :3] = (np.arange(IMG_W)[None, :, None] + frame) % 256
                img[..., 3] = 255
            if seg.has("cam0_rgb"):
                with seg.write("cam0_rgb", frame) as img:
                    img[..., 0] = frame % 256
                    img[..., 1] = np.arange(IMG_H)[:, None] * 4
                    img[..., 2] = 128
                    img[..., 3] = 255
            with seg.write("render_state", frame) as v:
                v.t_s, v.valid_fraction = t, 1.0
        else:
            with seg.write("heightmap_perceived", frame) as h:
                h[...] = truth(frame)[::2, ::2]
                h[(np.arange(NXC) + frame) % 5 == 0, :] = np.nan
            with seg.write("lidar_points", frame) as p:
                p[...] = points(frame)
            with seg.write("perc_state", frame) as v:
                v.t_s, v.coverage, v.cart_valid = t, 0.8, 1

    def close(self):
        self.seg = None


def make(scenario, role="dynamics", **kw):
    return StandIn(scenario, role, **kw)


def specs(pace_s: float = 0.0, **by_role) -> dict[str, ParticipantSpec]:
    """Specs of the three stand-in roles; ``by_role={'renderer': {'kill_at': 3}}``."""
    return {r: ParticipantSpec(r, "test_viewer_standins:make", f"test_viewer_standins:blocks_{r}",
                               kwargs={"role": r, "pace_s": pace_s, **by_role.get(r, {})})
            for r in ("dynamics", "renderer", "perception")}


def scenario(duration_s: float = 1.0, viewer: bool = True) -> Scenario:
    return Scenario(format_version=1, duration_s=duration_s, renderer="mock", viewer=viewer)


def test_standins_write_every_block_each_frame():
    run = simulate(scenario(0.5), specs())
    seg = run.segment
    last = scenario(0.5).frames
    for name in ("dyn_state", "heightmap_truth", "cam0_depth", "cam0_rgb", "perc_state", "heightmap_perceived",
                 "lidar_points"):
        assert seg.frame_of(name) == last, name
    assert np.array_equal(seg.view("heightmap_truth"), truth(last))
    assert int(np.isfinite(seg.view("lidar_points")[:, 0]).sum()) == int(valid_beams(last).sum())


def test_without_viewer_there_is_no_rgb_block():
    run = simulate(scenario(0.2, viewer=False), specs())
    assert not run.segment.has("cam0_rgb") and run.segment.has("cam0_depth")
