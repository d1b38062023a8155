"""Liveness by evidence of progress: start-up as its own phase, and no false faults on a busy machine.

The busy machine is real: ten processes spinning beside the run (cosim.testing.load.busy), so every member of
the ring gets a fraction of a core, as on a user's laptop with a browser open. A healthy run must complete; a
real hang must still be named on the right member (within IDLE_S + a few seconds under that load).
"""
from __future__ import annotations

import time
from pathlib import Path

import pytest

from cosim.errors import ParticipantHung
from cosim.runtime import liveness
from cosim.runtime.launcher import EXIT_RUN_ERROR, launch
from cosim.runtime.liveness import IDLE_S, STALL_S, Evidence, threads_progress
from cosim.scenario.config import Scenario
from cosim.testing import fakes
from cosim.testing.load import busy, promised

#: busy processes beside the loaded runs (2 cores: a load of 12 or more)
BUSY = 10
#: a hang under that load is named, and the launcher back, within this long of the fault
NAMED_UNDER_LOAD_S = 6.0
#: ... and on a quiet machine
NAMED_QUIET_S = 2.0


def scenario(duration_s: float = 1.0) -> Scenario:
    return Scenario(format_version=1, duration_s=duration_s, renderer="mock")


def since(stamp: Path) -> float:
    return time.monotonic() - float(stamp.read_text())


def test_threads_progress_sees_cpu_time_and_leaves_out_the_named_thread():
    import os
    import threading

    me = os.getpid()
    cpu0, _ = threads_progress(me)
    t_end = time.process_time() + 0.05
    while time.process_time() < t_end:
        pass
    cpu1, busy_now = threads_progress(me)
    assert cpu1 - cpu0 >= 40_000_000 and busy_now  # this thread ran (R) and gained >= 40 ms
    # a thread left out contributes nothing: leave out this (the only working) thread, then spin again
    tid = threading.get_native_id()
    rest0, _ = threads_progress(me, skip_tid=tid)
    t_end = time.process_time() + 0.05
    while time.process_time() < t_end:
        pass
    rest1, _ = threads_progress(me, skip_tid=tid)
    assert rest1 - rest0 < 20_000_000
    assert threads_progress(2**22 + 12345)[0] == -1  # no such process


def test_a_heartbeat_thread_starved_while_it_holds_the_gil_is_starvation_not_a_hang():
    """Preempted mid-beat (holding the GIL) on a busy machine, the heartbeat thread is runnable and gains no CPU
    time, while the working threads sleep on the GIL: the member is waited for. In a GIL deadlock the heartbeat
    thread is woken by the GIL's timed wait and gains CPU time between samples: no evidence, named after IDLE_S."""
    ms = 1_000_000
    starved = liveness.Progress((2, 5, 0), since_ns=0)
    starved.sample(0, cpu=100 * ms, busy=False, beat=(7 * ms, True))             # the count starts
    for t in range(1, 31):                                                        # 3 s of samples, 0.1 s apart
        starved.sample(t * 100 * ms, cpu=100 * ms, busy=False, beat=(7 * ms, True))
    assert starved.moved_ns == 3000 * ms                                          # waited for at every sample
    deadlock = liveness.Progress((2, 5, 0), since_ns=0)
    deadlock.sample(0, cpu=100 * ms, busy=False, beat=(7 * ms, True))
    for t in range(1, 31):                           # woken every 5 ms: a few us of CPU time between samples
        deadlock.sample(t * 100 * ms, cpu=100 * ms, busy=False, beat=(7 * ms + t * 40_000, t % 2 == 0))
    assert deadlock.moved_ns == 0 and (3000 * ms - deadlock.moved_ns) / 1e9 > IDLE_S
    sleeping = liveness.Progress((2, 5, 0), since_ns=0)                           # the beat thread asleep
    for t in range(0, 31):
        sleeping.sample(t * 100 * ms, cpu=100 * ms, busy=False, beat=(7 * ms, False))
    assert sleeping.moved_ns == 0


#: the watch's samples of a real false fault (perception of dusty at nice 19 beside ten busy processes, named
#: "stopped beating" before the watch counted its looks): seconds before the verdict, the working threads' CPU ms,
#: one of them runnable, the heartbeat thread's CPU ms, it runnable. The supervisor, starved too, looked 0.1-2.6 s
#: apart; the working threads were runnable at almost every look, and the last look came 1.17 s after the one before
STARVED_AT_NICE_19 = [
    (9.46, 1174.3, True, 132.0, False), (9.02, 1178.1, True, 132.1, True), (8.91, 1178.1, True, 132.1, True),
    (7.64, 1178.1, True, 132.6, True), (7.04, 1178.1, True, 132.8, True), (4.45, 1178.1, True, 133.6, False),
    (3.87, 1180.6, True, 134.0, False), (3.60, 1180.6, True, 134.1, True), (2.64, 1184.1, True, 134.6, True),
    (2.50, 1184.1, True, 134.6, False), (2.18, 1187.9, True, 135.0, False), (1.96, 1187.9, True, 135.0, False),
    (1.81, 1189.4, True, 135.2, False), (1.60, 1194.3, True, 135.3, True), (1.17, 1194.3, True, 135.4, True),
    (0.00, 1194.4, False, 135.9, True)]


def test_a_verdict_needs_idle_looks_in_a_row_not_one_look_after_a_long_gap():
    """The recorded false fault is no longer one: one idle look after a 1.17 s gap is not IDLE_LOOKS of them. A
    real deadlock is still named: after IDLE_S when looked at every 0.1 s, after IDLE_LOOKS looks when the
    supervisor looks every 0.5 s."""
    ms = 1_000_000
    p = liveness.Progress((3, 35, 0), since_ns=0)
    for ago, cpu, busy_now, beat, beat_runnable in STARVED_AT_NICE_19:
        now = int((10.0 - ago) * 1000) * ms
        p.sample(now, int(cpu * ms), busy_now, (int(beat * ms), beat_runnable))
    assert (now - p.moved_ns) / 1e9 > IDLE_S          # what the watch once named hung on
    assert p.idle_looks == 1 and p.idle_s(now) == 0.0
    for gap_ms, named_after_ms in ((100, 1000), (500, 2500)):
        deadlock = liveness.Progress((3, 35, 0), since_ns=0)
        for k in range(100):                     # nothing moves: no CPU time, nothing runnable
            t = k * gap_ms * ms
            deadlock.sample(t, cpu=100 * ms, busy=False, beat=(7 * ms + k * 40_000, False))
            if deadlock.idle_s(t) >= IDLE_S:
                break
        assert t == named_after_ms * ms and deadlock.idle_looks >= liveness.IDLE_LOOKS, (gap_ms, t)


def test_evidence_tells_a_sleeping_process_from_a_spinning_one():
    import subprocess
    import sys

    sleeper = subprocess.Popen([sys.executable, "-c", "import time; print('up', flush=True); time.sleep(60)"],
                               stdout=subprocess.PIPE, text=True)
    spinner = subprocess.Popen([sys.executable, "-c", "print('up', flush=True)\nwhile True: pass"],
                               stdout=subprocess.PIPE, text=True)
    try:
        assert sleeper.stdout.readline() == spinner.stdout.readline() == "up\n"  # both interpreters started
        ev_sleep, ev_spin = Evidence(sleeper.pid), Evidence(spinner.pid)
        ev_sleep.idle_s(), ev_spin.idle_s()
        t_end, looks = time.monotonic() + 1.2 * IDLE_S, 0
        while time.monotonic() < t_end or looks < liveness.IDLE_LOOKS:   # a verdict needs that many looks
            time.sleep(0.1)
            idle_spin, idle_sleep = ev_spin.idle_s(), ev_sleep.idle_s()
            looks += 1
        assert idle_sleep > IDLE_S
        assert idle_spin < 0.5 and ev_spin.cpu_s > 0  # runnable, and it ran (however starved)
    finally:
        sleeper.kill(), spinner.kill()
        sleeper.wait(), spinner.wait()


def test_a_start_up_that_makes_progress_is_waited_for_and_reported(tmp_path, shm_clean, monkeypatch, caplog):
    """The renderer burns 2.5 s of CPU in ``start`` in one call that keeps the GIL (its beat ages): slow, not
    hung; the launcher says what it waits for."""
    monkeypatch.setattr(liveness, "STARTUP_REPORT_S", 1.0)
    caplog.set_level("INFO", logger="cosim.runtime.launcher")
    res = launch(scenario(), tmp_path / "run", specs=fakes.specs(renderer={"start_busy_s": 2.5 * STALL_S}),
                 console_log=False)
    assert res.error is None and res.completed
    log = (tmp_path / "run" / "log.txt").read_text()
    assert "renderer: compiling shaders (a stand-in), " in log and "waiting for it" in log


@pytest.mark.parametrize("pipelined", [False, True])
def test_a_start_up_that_makes_no_progress_is_named_on_the_stuck_member(pipelined, tmp_path, shm_clean):
    stamp = tmp_path / "stamp"
    make = fakes.pipelined_specs if pipelined else fakes.specs
    res = launch(scenario(), tmp_path / "run",
                 specs=make(perception={"start_block": True, "stamp_file": str(stamp)}), console_log=False)
    took = since(stamp)
    assert isinstance(res.error, ParticipantHung) and res.error.process == "perception", res.error
    assert "is blocked in start-up (waiting for a licence server), before frame 0" in str(res.error)
    assert res.exit_code == EXIT_RUN_ERROR and res.summary["frames"] == 0
    # the start-up is looked at LOOK_AFTER_S after it began
    assert took < promised(NAMED_QUIET_S, NAMED_UNDER_LOAD_S) + IDLE_S


def test_a_healthy_run_on_a_busy_machine_completes(tmp_path, shm_clean):
    """Every member starved (ten busy processes on the cores), a member also in a 2.5 s call that keeps the GIL:
    no fault."""
    with busy(BUSY):
        res = launch(scenario(duration_s=2.0), tmp_path / "run",
                     specs=fakes.pipelined_specs(renderer={"busy_at": 3, "busy_s": 2.5 * STALL_S}), console_log=False)
    assert res.error is None and res.completed, res.error


#: fault -> words of the message; every fault under both schedules (three in the quick suite, the rest -m slow)
HANGS = {"deadlock_at": "stopped beating during frame 3", "hang_at": "is blocked during frame 3",
         "stop_at": "is stopped during frame 3"}
QUICK = {("deadlock_at", False), ("hang_at", True), ("stop_at", True)}


@pytest.mark.parametrize("fault,pipelined", [
    pytest.param(f, p, marks=() if (f, p) in QUICK else pytest.mark.slow) for f in HANGS for p in (False, True)])
def test_a_real_hang_on_a_busy_machine_is_named_on_the_right_member(fault, pipelined, tmp_path, shm_clean):
    words = HANGS[fault]
    stamp = tmp_path / "stamp"
    make = fakes.pipelined_specs if pipelined else fakes.specs
    with busy(BUSY):
        res = launch(scenario(duration_s=3.0), tmp_path / "run",
                     specs=make(dynamics={fault: 3, "stamp_file": str(stamp)}), console_log=False)
        took = since(stamp)
    assert isinstance(res.error, ParticipantHung) and res.error.process == "dynamics", res.error
    assert words in str(res.error)
    assert took < NAMED_UNDER_LOAD_S, f"named {took:.1f} s after the fault"
