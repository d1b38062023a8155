"""The pipelined schedule (cosim.runtime.pipeline): the plan, which schedule a run gets, overlap and order over
OS processes with the stand-ins, faults named within 2 s, and byte-identical results against the token ring."""
from __future__ import annotations

import os
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from cosim.errors import HandoffTimeout, ParticipantCrashed, ParticipantDied, ParticipantHung
from cosim.runtime import pipeline
from cosim.runtime.launcher import EXIT_RUN_ERROR, launch
from cosim.runtime.pipeline import Edge, Gates, PipePlan, effective_schedule
from cosim.runtime.specs import DEFAULT_SPECS, ring_specs
from cosim.scenario.config import Scenario
from cosim.scenario.loader import load_scenario, packaged_scenarios
from cosim.testing import fakes
from cosim.testing.load import loaded, promised
from cosim.testing.processes import ring_children
from shm_schema import Field, Schema, Segment, StructBlock

ROLES = ("dynamics", "renderer", "perception")
#: the promise: a dead, stopped or hung child ends the run within this long after it happens
STOP_WITHIN_S = 2.0


def scenario(duration_s=1.0, handoff_timeout_s=30.0, **timing) -> Scenario:
    sc = Scenario(format_version=1, duration_s=duration_s, renderer="mock")
    return sc.model_copy(update={"timing": sc.timing.model_copy(update={"handoff_timeout_s": handoff_timeout_s,
                                                                          **timing})})


def children_of(pid: int) -> list[int]:
    """Worker processes of launcher ``pid`` (spawned, or forked by its fork server; not its resource tracker)."""
    return ring_children(pid)


# -- the plan ------------------------------------------------------------------------------------------------------
def test_plan_edges_and_the_frames_each_one_carries():
    plan = PipePlan.build({"dynamics": {"perception": 2}, "renderer": {"dynamics": 0},
                           "perception": {"renderer": 0, "dynamics": 0}}, frames=10, deferred=("perception",))
    assert plan.deferred == ("perception",)
    assert {e.key for e in plan.inputs("perception")} == {"renderer>perception", "dynamics>perception"}
    assert {e.key for e in plan.inputs("supervisor")} == {f"{m}>supervisor" for m in ROLES}
    back = Edge("perception", "dynamics", 2)
    assert [plan.read(back, f) for f in (-1, 0, 8, 9)] == [False, True, True, False]   # P(9) is read by nobody
    assert len(plan.semaphore_names) == 2 * len(plan.edges)


@pytest.mark.parametrize("reads,match", [
    ({"a": {"b": 0}, "b": {"a": 0}}, "same frame: a -> b -> a"),
    ({"a": {"c": 0}, "b": {}}, "not another member"),
    ({"a": {"b": -1}, "b": {}}, "lag must be >= 0"),
])
def test_plan_refuses_what_cannot_run(reads, match):
    with pytest.raises(ValueError, match=match):
        PipePlan.build(reads, frames=3)


def test_which_schedule_a_run_gets(monkeypatch):
    sc = Scenario(format_version=1)
    reads = {s.name: s.reads_of(sc) for s in ring_specs(sc)}
    assert reads == {"dynamics": {"perception": 2}, "renderer": {"dynamics": 0},
                     "perception": {"renderer": 0, "dynamics": 0}}
    l0 = sc.model_copy(update={"timing": sc.timing.model_copy(update={"latency_frames": 0})})
    assert DEFAULT_SPECS["dynamics"].reads_of(l0) == {"perception": 1}
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1})
    assert effective_schedule(sc, reads)[0] == "pipelined"
    seq = sc.model_copy(update={"timing": sc.timing.model_copy(update={"schedule": "sequential"})})
    assert effective_schedule(seq, reads) == ("sequential", "timing.schedule: sequential")
    assert effective_schedule(sc, {"dynamics": {}})[0] == "sequential"                 # ground truth alone
    assert "no reads declared for renderer" in effective_schedule(sc, {**reads, "renderer": None})[1]
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0})
    assert effective_schedule(sc, reads) == ("sequential", "one core")
    l3 = sc.model_copy(update={"timing": sc.timing.model_copy(update={"latency_frames": 3})})
    assert DEFAULT_SPECS["dynamics"].reads_of(l3) == {"perception": 2}      # taken at 2, used at 4 frames back
    gt = sc.model_copy(update={"feedback": "ground_truth"})
    assert DEFAULT_SPECS["dynamics"].reads_of(gt) == {}


# -- threads over an in-process segment: the waits themselves -----------------------------------------------------
def _segment(members):
    blocks = [StructBlock(f"out_{m}", m, (Field("v", ""), Field("seen", ""))) for m in members]
    return Segment.local(Schema(blocks, list(members) + ["supervisor"]))


class _Member:
    """Takes its producers' ``v`` at the plan's lags into a history, keyed by the block's stamp; uses the value
    ``uses[producer]`` frames back; sleeps ``work_s``; writes v = frame + the sum of what it used."""

    def __init__(self, name, seg, plan, uses, work_s, log):
        self.name, self.seg, self.plan, self.uses, self.work_s, self.log = name, seg, plan, uses, work_s, log
        self.history = {}

    def step(self, frame):
        for e in self.plan.inputs(self.name):
            if self.plan.read(e, frame - e.lag):
                block = f"out_{e.producer}"
                assert self.seg.frame_of(block) == frame - e.lag
                self.history[(e.producer, frame - e.lag)] = self.seg.view(block).v
        seen = sum(self.history[(p, frame - lag)] for p, lag in self.uses.items() if frame - lag >= 0)
        self.log.append((self.name, "start", frame, time.monotonic()))

        def rest():
            time.sleep(self.work_s)
            self.pending = (frame, seen)
            self.log.append((self.name, "end", frame, time.monotonic()))
        if self.name in self.plan.deferred:          # overlapping: inputs given back when step returns
            return rest
        rest()
        self.flush()
        return None

    def flush(self):
        frame, seen = self.pending
        with self.seg.write(f"out_{self.name}", frame) as v:
            v.v, v.seen = frame + seen, seen


def _run_threads(reads, uses, frames, work_s):
    """Members as threads (threading semaphores) and a supervisor collecting each frame's rows."""
    members = tuple(reads)
    seg = _segment(members)
    plan = PipePlan.build(reads, frames, deferred=("perception",))
    sems = {n: threading.Semaphore(0) for n in plan.semaphore_names}
    log, rows, errors = [], {}, []

    def member(name):
        try:
            segs = Segment(seg._buf, seg.schema, None, owner=False)        # each "process" its own views
            p = _Member(name, segs, plan, uses[name], work_s, log)
            pipeline.member_loop(name, p, segs, Gates(segs, plan, sems, name), plan, startup_timeout_s=10,
                                 handoff_timeout_s=10)
        except BaseException as exc:  # noqa: BLE001 - the test reports it
            errors.append(exc)

    threads = [threading.Thread(target=member, args=(m,)) for m in members]
    for t in threads:
        t.start()
    sup = Segment(seg._buf, seg.schema, None, owner=False)
    pipeline.supervise(sup, plan, Gates(sup, plan, sems, "supervisor"), startup_timeout_s=10, handoff_timeout_s=10,
                       on_take=lambda m, f: rows.setdefault(f, {}).update({m: sup.view(f"out_{m}").v}),
                       on_frame=lambda f, t: None)
    for t in threads:
        t.join()
    assert not errors, errors
    return rows, log


def _serial(reads, frames):
    """The same members run one after the other, frame by frame (the token ring's order)."""
    hist = {m: {} for m in reads}
    for f in range(frames + 1):
        for m, ins in reads.items():
            hist[m][f] = f + sum(hist[p][f - lag] for p, lag in ins.items() if f - lag >= 0)
    return {f: {m: float(hist[m][f]) for m in reads} for f in range(frames + 1)}


@pytest.mark.parametrize("latency", [0, 1, 2, 3, 5])
def test_threads_read_exactly_their_frames_and_overlap(latency):
    """The members' own edges (dynamics takes perception's output min(1 + L, 2) frames back and uses it 1 + L
    frames back): every member reads exactly the producer frames it declares (the values equal the serial
    ring's), nothing deadlocks, and (L >= 1) dynamics of frame k + 1 works beside the renderer of frame k, the
    renderer of k + 1 beside perception (overlapping, as the real one) of frame k."""
    uses = {"dynamics": {"perception": 1 + latency}, "renderer": {"dynamics": 0},
            "perception": {"renderer": 0, "dynamics": 0}}
    reads = {**uses, "dynamics": {"perception": min(1 + latency, 2)}}
    frames = 12
    rows, log = _run_threads(reads, uses, frames, work_s=0.02)
    assert rows == _serial(uses, frames)
    busy = {}
    for name, kind, frame, t in log:
        busy.setdefault((name, frame), {})[kind] = t
    spans = {k: (v["start"], v["end"]) for k, v in busy.items()}

    def overlap(a, b):
        return min(spans[a][1], spans[b][1]) - max(spans[a][0], spans[b][0]) > 0.0

    # most frames (a loaded host may delay a thread past its neighbour's work now and then); on a busy machine
    # (more runnable work than cores) threads cannot run side by side, so the overlap is asked of a quiet one
    if latency >= 1 and not loaded():
        ks = range(2, frames - 1)
        assert sum(overlap(("dynamics", k + 1), ("renderer", k)) for k in ks) > len(ks) / 2
        assert sum(overlap(("renderer", k + 1), ("perception", k)) for k in ks) > len(ks) / 2


# -- launched runs with the stand-ins --------------------------------------------------------------------------------
def test_launched_pipeline_completes_and_overlaps(tmp_path, shm_clean):
    """Perception's rest takes 30 ms a frame: pipelined, the renderer of the next frame runs meanwhile."""
    sc = scenario(duration_s=1.0)
    res = launch(sc, tmp_path / "run", specs=fakes.pipelined_specs(perception={"defer": True, "rest_s": 0.03}),
                 console_log=False)
    assert res.exit_code == 0 and res.completed, res.error
    assert res.summary["ring"]["schedule"] == "pipelined"
    rows = (tmp_path / "run" / "timeseries.csv").read_text().splitlines()
    header = rows[0].split(",")
    body = [dict(zip(header, r.split(","))) for r in rows[1:]]
    assert [int(r["frame"]) for r in body] == list(range(sc.frames + 1))
    assert all(int(r["fake_ren.dyn_frame"]) == k and int(r["fake_perc.img_frame"]) == k for k, r in enumerate(body)), rows
    trace = {r: res.arrays[f"trace_{r}"][:, 1] for r in ROLES}
    # the renderer stamps frame k + 1 before perception's 30 ms rest of frame k has ended
    ahead = trace["renderer"][1:] < trace["perception"][:-1] + 30_000_000
    assert ahead.mean() > 0.5
    assert not children_of(os.getpid())


@pytest.mark.parametrize("role", ROLES)
def test_crash_is_named_under_the_pipeline(role, tmp_path, shm_clean):
    res = launch(scenario(), tmp_path / "run", specs=fakes.pipelined_specs(**{role: {"crash_at": 4}}),
                 console_log=False)
    assert res.exit_code == EXIT_RUN_ERROR and isinstance(res.error, ParticipantCrashed)
    assert res.error.process == role and res.error.frame == 4 and "Traceback" in res.error.detail
    assert res.summary["frames"] <= 4 and res.summary["error"]["process"] == role
    assert not children_of(os.getpid())


def test_kill9_is_named_within_2_s_under_the_pipeline(tmp_path, shm_clean):
    stamp = tmp_path / "killed_at"
    res = launch(scenario(duration_s=5.0), tmp_path / "run",
                 specs=fakes.pipelined_specs(renderer={"kill_at": 30, "stamp_file": str(stamp)}), console_log=False)
    returned = time.monotonic()
    assert isinstance(res.error, ParticipantDied) and res.error.process == "renderer"
    assert "SIGKILL" in str(res.error) and "frame 30" in str(res.error)
    assert returned - float(stamp.read_text()) < promised(STOP_WITHIN_S)
    assert not children_of(os.getpid())


def test_a_stopped_child_is_named_within_2_s_under_the_pipeline(tmp_path, shm_clean):
    stamp = tmp_path / "stamp"
    res = launch(scenario(duration_s=3.0), tmp_path / "run",
                 specs=fakes.pipelined_specs(perception={"stop_at": 5, "stamp_file": str(stamp)}), console_log=False)
    took = time.monotonic() - float(stamp.read_text())
    assert isinstance(res.error, ParticipantHung) and res.error.process == "perception"
    assert "is stopped during frame 5" in str(res.error)
    assert took < promised(STOP_WITHIN_S)
    assert not children_of(os.getpid())


def test_a_blocked_member_is_named_under_the_pipeline_not_who_waits_for_it(tmp_path, shm_clean):
    res = launch(scenario(), tmp_path / "run", specs=fakes.pipelined_specs(renderer={"hang_at": 2}),
                 console_log=False)
    assert isinstance(res.error, ParticipantHung) and res.error.process == "renderer", res.error
    assert "is blocked during frame 2" in str(res.error)
    assert res.summary["frames"] <= 2
    assert not children_of(os.getpid())


def test_a_runaway_meets_its_cpu_budget_under_the_pipeline(tmp_path, shm_clean):
    res = launch(scenario(handoff_timeout_s=1.0), tmp_path / "run", specs=fakes.pipelined_specs(renderer={"spin_at": 2}),
                 console_log=False)
    assert type(res.error) is HandoffTimeout and res.error.process == "renderer", res.error
    assert "did not finish frame 2 within its CPU budget" in str(res.error)
    assert not children_of(os.getpid())


# -- real runs: byte-identical timeseries under both schedules --------------------------------------------------------
def _both_schedules(name: str, latency: int, duration_s: float, tmp_path: Path) -> None:
    base = load_scenario(packaged_scenarios()[name])
    out = {}
    for schedule in ("sequential", "pipelined"):
        sc = base.model_copy(update={"duration_s": duration_s, "outputs": base.outputs.model_copy(
            update={"figures": False}), "timing": base.timing.model_copy(update={"latency_frames": latency,
                                                                                 "schedule": schedule})})
        res = launch(sc, tmp_path / schedule, console_log=False)
        assert res.completed, res.error
        assert res.summary["ring"]["schedule"] == schedule
        out[schedule] = (tmp_path / schedule / "timeseries.csv").read_bytes()
    assert len(out["pipelined"].splitlines()) == round(duration_s / base.timing.sensor_period_s) + 2
    assert out["pipelined"] == out["sequential"]
    for m in ("heightmap_truth.npy", "heightmap_perceived.npy"):
        if (tmp_path / "sequential" / m).exists():
            np.testing.assert_array_equal(np.load(tmp_path / "pipelined" / m), np.load(tmp_path / "sequential" / m))


@pytest.mark.parametrize("latency", [1, 3])
def test_default_scenario_identical_under_both_schedules(latency, tmp_path, shm_clean, monkeypatch):
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1})
    _both_schedules("default", latency, 4.0, tmp_path)


@pytest.mark.slow
@pytest.mark.parametrize("latency", [1, 3])
@pytest.mark.parametrize("name", sorted(packaged_scenarios()))
def test_every_packaged_scenario_identical_under_both_schedules(name, latency, tmp_path, shm_clean, monkeypatch):
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1})
    _both_schedules(name, latency, 12.0, tmp_path)
