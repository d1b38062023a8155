"""The lockstep ring over OS processes with stand-in participants: order, outputs, faults, signals."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from cosim.errors import FrameMismatch, HandoffTimeout, ParticipantCrashed, ParticipantDied, ParticipantHung
from cosim.runtime.inprocess import simulate
from cosim.runtime.launcher import EXIT_INTERRUPTED, EXIT_RUN_ERROR, launch
from cosim.runtime.liveness import IDLE_S
from cosim.runtime.lockstep import RingPlan, Token
from cosim.scenario.config import Scenario
from cosim.testing import fakes
from cosim.testing.load import promised
from cosim.testing.processes import ring_children
from shm_schema import Field, Schema, Segment, StructBlock

ROLES = ("dynamics", "renderer", "perception")
#: the promise: a dead or hung child ends the run within this long after it happens
STOP_WITHIN_S = 2.0


def scenario(duration_s=1.0, handoff_timeout_s=30.0) -> Scenario:
    sc = Scenario(format_version=1, duration_s=duration_s, renderer="mock")
    return sc.model_copy(update={"timing": sc.timing.model_copy(update={"handoff_timeout_s": handoff_timeout_s})})


def children_of(pid: int) -> list[int]:
    """Worker processes of launcher ``pid`` (spawned, or forked by its fork server; not its resource tracker)."""
    return ring_children(pid)


def test_ring_order_is_the_recorded_trace(tmp_path, shm_clean):
    res = launch(scenario(), tmp_path / "run", specs=fakes.specs(), console_log=False)
    assert res.exit_code == 0 and res.completed
    n = scenario().frames + 1
    assert res.summary["frames"] == n
    ts = (tmp_path / "run" / "timeseries.csv").read_text().splitlines()
    assert len(ts) == n + 1
    header = ts[0].split(",")
    rows = [dict(zip(header, line.split(","))) for line in ts[1:]]
    for k, row in enumerate(rows):
        # each role saw the previous role's output of the same frame, and dynamics saw perception's of k-1
        assert int(row["frame"]) == k
        assert int(row["fake_ren.dyn_frame"]) == k
        assert int(row["fake_perc.img_frame"]) == k
        assert int(row["fake_dyn.perc_frame"]) == k - 1
        assert float(row["fake_ren.x_seen_m"]) == float(row["fake_dyn.x_m"])
    assert not children_of(os.getpid())


def test_inprocess_trace_matches_order():
    run = simulate(scenario(), fakes.specs())
    seg = run.segment
    t = np.stack([seg.view(f"trace_{r}")[:, 1] for r in ROLES], axis=1)  # (frames, roles) monotonic ns
    flat = t.reshape(-1)
    assert np.all(np.diff(flat) > 0), "steps must follow dynamics -> renderer -> perception, frame by frame"
    s = run.recorder.series()
    assert np.array_equal(s["fake_perc.img_frame"], s["frame"])


def test_os_ring_trace_is_strictly_ordered(tmp_path, shm_clean):
    """Each role stamps CLOCK_MONOTONIC (system-wide) per frame: across processes they interleave in ring order."""
    res = launch(scenario(), tmp_path / "run", specs=fakes.specs(), console_log=False)
    assert res.completed
    frames = np.stack([res.arrays[f"trace_{r}"][:, 0] for r in ROLES], axis=1)
    stamps = np.stack([res.arrays[f"trace_{r}"][:, 1] for r in ROLES], axis=1)
    assert np.array_equal(frames, np.repeat(np.arange(scenario().frames + 1)[:, None], 3, axis=1))
    assert np.all(np.diff(stamps.reshape(-1)) > 0), "dynamics -> renderer -> perception, frame after frame"
    assert set(res.summary["timing_ms"]) == {"dynamics", "render", "perception", "handoff", "frame"}
    assert all(v >= 0 for v in res.summary["timing_ms"].values())


@pytest.mark.parametrize("role", ROLES)
def test_crash_comes_back_with_traceback(role, tmp_path, shm_clean):
    t0 = time.monotonic()
    res = launch(scenario(), tmp_path / "run", specs=fakes.specs(**{role: {"crash_at": 4}}), console_log=False)
    assert time.monotonic() - t0 < promised(15, 60)
    assert res.exit_code == EXIT_RUN_ERROR and not res.completed
    assert isinstance(res.error, ParticipantCrashed)
    assert res.error.process == role and res.error.frame == 4
    assert "injected crash" in str(res.error) and "Traceback" in res.error.detail and "fakes.py" in res.error.detail
    assert res.summary["frames"] == 4 and res.summary["completed"] is False
    assert res.summary["error"]["process"] == role
    log = (tmp_path / "run" / "log.txt").read_text()
    assert "injected crash" in log and f"cosim-{role}" in log
    assert len((tmp_path / "run" / "timeseries.csv").read_text().splitlines()) == 1 + 4
    assert not children_of(os.getpid())


@pytest.mark.parametrize("role", ROLES)
def test_kill9_is_named_and_stops_fast(role, tmp_path, shm_clean):
    res = launch(scenario(), tmp_path / "run", specs=fakes.specs(**{role: {"kill_at": 3}}), console_log=False)
    assert isinstance(res.error, ParticipantDied)
    assert res.error.process == role and res.error.frame == 3
    assert "SIGKILL" in str(res.error) and "frame 3" in str(res.error)
    assert res.summary["frames"] == 3
    assert res.summary["wall_time_s"] < promised(10, 40)
    assert not children_of(os.getpid())


@pytest.mark.parametrize("role", ROLES)
def test_a_blocked_member_is_named_hung_not_its_waiting_peers(role, tmp_path, shm_clean):
    """It beats but its working threads sleep without CPU time (a lock that is never released): named as blocked
    within about IDLE_S, whatever the hand-off timeout."""
    t0 = time.monotonic()
    res = launch(scenario(), tmp_path / "run", specs=fakes.specs(**{role: {"hang_at": 2}}), console_log=False)
    took = time.monotonic() - t0
    assert isinstance(res.error, ParticipantHung) and res.error.process == role, res.error
    assert f"{role} (pid " in str(res.error) and "is blocked during frame 2 (stepping)" in str(res.error)
    assert res.summary["frames"] == 2
    # start-up (3 interpreters) + 2 frames + IDLE_S + at most STOP_WITHIN_S to stop
    assert took < IDLE_S + promised(STOP_WITHIN_S + 8, 40)
    assert not children_of(os.getpid())


@pytest.mark.parametrize("role", ROLES)
def test_a_runaway_meets_its_cpu_budget_naming_it(role, tmp_path, shm_clean):
    """A loop that never ends beats and uses CPU time: it is stopped once it has spent the hand-off timeout of
    its own CPU time on one frame."""
    res = launch(scenario(handoff_timeout_s=1.0), tmp_path / "run", specs=fakes.specs(**{role: {"spin_at": 2}}),
                 console_log=False)
    assert type(res.error) is HandoffTimeout and res.error.process == role, res.error
    assert f"{role} (pid " in str(res.error) and "did not finish frame 2 within its CPU budget" in str(res.error)
    assert "timing.handoff_timeout_s = 1 s" in str(res.error)
    assert not children_of(os.getpid())


def test_silent_exit_is_a_death(tmp_path, shm_clean):
    res = launch(scenario(), tmp_path / "run", specs=fakes.specs(renderer={"exit_at": 1}), console_log=False)
    assert isinstance(res.error, ParticipantDied) and "exit status 3" in str(res.error)


def test_detection_latency_after_death(tmp_path, shm_clean):
    """From the kill to the launcher's return (children gone, outputs written) stays under 2 s."""
    stamp = tmp_path / "killed_at"
    sc = scenario(duration_s=5.0)
    res = launch(sc, tmp_path / "run", specs=fakes.specs(perception={"kill_at": 40, "stamp_file": str(stamp)}),
                 console_log=False)
    returned = time.monotonic()
    assert isinstance(res.error, ParticipantDied)
    assert returned - float(stamp.read_text()) < promised(STOP_WITHIN_S)
    assert res.summary["frames"] == 40
    log = (tmp_path / "run" / "log.txt").read_text()
    assert "died with signal SIGKILL during frame 40" in log
    assert not children_of(os.getpid())


def test_token_checks_frame_ids():
    schema = Schema([StructBlock("s", "a", [Field("x")])], ["a", "b"])
    seg = Segment.local(schema)

    class Sem:
        def __init__(self):
            self.n = 0

        def release(self):
            self.n += 1

        def acquire(self, timeout=None):
            if self.n:
                self.n -= 1
                return True
            return False

    tok = Token(seg, {"a": Sem(), "b": Sem()})
    tok.give("b", 3)
    with pytest.raises(FrameMismatch, match="b expected the token of frame 4 but received frame 3"):
        tok.take("b", 4, 1.0)
    with pytest.raises(HandoffTimeout, match="b waited 0.1 s for the token of frame 5"):
        tok.take("b", 5, 0.1)
    assert RingPlan(("a", "b"), 3).next_of("b") == "supervisor"


def test_same_scenario_and_seed_give_identical_timeseries(tmp_path, shm_clean):
    a = launch(scenario(), tmp_path / "a", specs=fakes.specs(), console_log=False)
    b = launch(scenario(), tmp_path / "b", specs=fakes.specs(), console_log=False)
    assert a.completed and b.completed
    assert (tmp_path / "a" / "timeseries.csv").read_bytes() == (tmp_path / "b" / "timeseries.csv").read_bytes()


SIGNAL_SCRIPT = textwrap.dedent("""
    import sys
    sys.path[:0] = [{repo!r}, {tests!r}]  # this checkout's code, not an installed copy
    from cosim.testing import fakes
    from cosim.scenario.config import Scenario
    from cosim.runtime.launcher import launch
    if __name__ == "__main__":
        sc = Scenario(format_version=1, duration_s=3600.0, renderer="mock")
        res = launch(sc, {out!r}, specs=fakes.specs(), console_log=False)
        sys.exit(res.exit_code)
""")


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_signal_stops_cleanly(sig, tmp_path, shm_clean):
    out = tmp_path / "run"
    script = tmp_path / "run_it.py"
    script.write_text(SIGNAL_SCRIPT.format(repo=str(Path(__file__).parent.parent), tests=str(Path(__file__).parent),
                                           out=str(out)))
    proc = subprocess.Popen([sys.executable, str(script)], cwd=Path(__file__).parent.parent)
    # wait until the ring has turned a few frames, reading the run's own segment (self-describing)
    deadline = time.monotonic() + 60
    frame = -1
    while time.monotonic() < deadline and frame < 5:
        time.sleep(0.1)
        names = [p.name for p in Path("/dev/shm").glob(f"cosim-{proc.pid}-*")]
        if names:
            try:
                seg = Segment.attach(names[0])
                frame = int(seg.slot("supervisor")["frame"])
                seg.close()
            except FileNotFoundError:
                pass
    assert frame >= 5, "the ring did not start turning"
    kids = children_of(proc.pid)
    assert kids, "the launcher should have children by now"
    t0 = time.monotonic()
    proc.send_signal(sig)
    code = proc.wait(timeout=10)
    assert time.monotonic() - t0 < promised(STOP_WITHIN_S)
    assert code == EXIT_INTERRUPTED
    import json

    summary = json.loads((out / "summary.json").read_text())
    assert summary["completed"] is False and summary["frames"] > 1
    assert signal.Signals(sig).name in summary["error"]["message"]
    assert not list(Path("/dev/shm").glob(f"cosim-{proc.pid}-*")), "the stopped launcher left its segment"
    time.sleep(0.2)
    alive = [k for k in kids if Path(f"/proc/{k}").exists() and "Z" not in Path(f"/proc/{k}/stat").read_text().split()[2]]
    assert not alive, f"orphans left: {alive}"
