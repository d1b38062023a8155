"""Run faults beyond crashes: stopped and deadlocked children, a stopped recorder, a killed launcher,
full disks, unusable run directories, determinism. Real launched runs with the stand-ins of cosim/testing/fakes.py."""
from __future__ import annotations

import errno
import fcntl
import json
import os
import re
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from cosim.errors import HandoffTimeout, OutputError, ParticipantHung, RecordingFailed
from cosim.recording import RecordOptions, mcap_sink
from cosim.runtime import stream
from cosim.runtime.launcher import EXIT_RUN_ERROR, launch
from cosim.runtime.liveness import STALL_S, process_state
from cosim.runtime.rundir import LOCK_NAME, RunDirError
from cosim.scenario.config import Scenario
from cosim.testing import fakes
from cosim.testing.load import promised

REPO = Path(__file__).resolve().parent.parent
#: the promise: a stopped or deadlocked child is named, and the launcher has returned, within this long
NAMED_WITHIN_S = 2.0


def scenario(duration_s=1.0, handoff_timeout_s=30.0) -> Scenario:
    sc = Scenario(format_version=1, duration_s=duration_s, renderer="mock")
    return sc.model_copy(update={"timing": sc.timing.model_copy(update={"handoff_timeout_s": handoff_timeout_s})})


def since_stamp(stamp: Path) -> float:
    """Seconds from the fault (the stand-in's CLOCK_MONOTONIC stamp) to now."""
    return time.monotonic() - float(stamp.read_text())


@pytest.mark.parametrize("role,fault,at,words", [
    ("renderer", "stop_at", -2, "is stopped in start-up"),
    ("perception", "stop_at", 5, "is stopped during frame 5"),
    ("dynamics", "deadlock_at", 3, "stopped beating during frame 3"),
])
def test_a_child_that_stops_running_is_named_within_2_s(role, fault, at, words, tmp_path, shm_clean):
    stamp = tmp_path / "stamp"
    res = launch(scenario(duration_s=3.0), tmp_path / "run",
                 specs=fakes.specs(**{role: {fault: at, "stamp_file": str(stamp)}}), console_log=False)
    took = since_stamp(stamp)
    assert isinstance(res.error, ParticipantHung), res.error
    assert res.error.process == role and words in str(res.error)
    assert took < promised(NAMED_WITHIN_S)
    assert res.exit_code == EXIT_RUN_ERROR
    assert res.summary["frames"] == max(at, 0) and res.summary["status"] == "failed"
    assert all(code is not None for code in res.children.values())
    if fault == "deadlock_at":  # what its threads did is told in summary.json and log.txt (the console is spared)
        threads = res.summary["error"]["threads"]
        pid = re.search(r"\(pid (\d+)\)", str(res.error)).group(1)
        main = next(t for t in threads if t.startswith(f"tid {pid} "))  # the process's main thread
        assert " S cpu " in main, main                                # the deadlocked thread sleeps in C
        assert any(t.startswith("tid ") and "run-queue wait" in t and "voluntary" in t for t in threads), threads
        assert "the watch's samples" in "\n".join(threads)
        assert "the threads of dynamics when it was named" in (tmp_path / "run" / "log.txt").read_text()


def test_a_runaway_frame_meets_its_cpu_budget_not_the_heartbeat(tmp_path, shm_clean):
    """A frame that never ends but keeps beating and using CPU time is a runaway, named by its CPU budget."""
    res = launch(scenario(handoff_timeout_s=STALL_S + 0.5), tmp_path / "run",
                 specs=fakes.specs(renderer={"spin_at": 2}), console_log=False)
    assert type(res.error) is HandoffTimeout and "renderer (pid" in str(res.error)
    assert "did not finish frame 2 within its CPU budget" in str(res.error)


def test_a_child_busy_in_one_long_call_that_keeps_the_gil_is_slow_not_hung(tmp_path, shm_clean):
    """Its heartbeat thread cannot beat (like a long GL draw), but it uses CPU time: the run completes."""
    res = launch(scenario(), tmp_path / "run", specs=fakes.specs(renderer={"busy_at": 2, "busy_s": 2.5 * STALL_S}),
                 console_log=False)
    assert res.error is None and res.completed


def _faulty_recording(frame: int, sig: int):
    """An MCAP sink whose recorder process gets ``sig`` at ``frame`` (4 slots: the ring soon waits for a stopped
    one)."""
    make = mcap_sink(RecordOptions(queue_frames=4))

    class Sink:
        def __init__(self, rec):
            self.rec = rec

        def __call__(self, seg, f):
            if f == frame:
                os.kill(self.rec._proc.pid, sig)
                if sig == signal.SIGKILL:
                    self.rec._proc.join(5)
            self.rec(seg, f)

        def close(self):
            self.rec.close()

        @property
        def error(self):
            return self.rec.error

    return lambda sc, run_dir, seg: Sink(make(sc, run_dir, seg))


@pytest.mark.parametrize("stop_at", [3, 10])
def test_a_stopped_recorder_never_holds_the_run(stop_at, tmp_path, shm_clean, capfd):
    """Stopped mid-run (the sink waits for a slot) or at the last frame (``close`` waits for it): it is ended
    and the run finishes with all its own outputs; no traceback."""
    t0 = time.monotonic()
    res = launch(scenario(), tmp_path / "run", specs=fakes.specs(), console_log=True, sinks=[_faulty_recording(stop_at, signal.SIGSTOP)])
    _check_ran_without_its_recording(res, "is stopped (SIGSTOP)")
    assert time.monotonic() - t0 < promised(20, 80)
    log = (tmp_path / "run" / "log.txt").read_text()
    assert "is stopped (SIGSTOP)" in log and "Traceback" not in log
    assert "Traceback" not in capfd.readouterr().err
    assert len((tmp_path / "run" / "timeseries.csv").read_text().splitlines()) == 1 + 11


def test_a_stopped_viewer_is_ended_with_the_run(tmp_path, shm_clean):
    from cosim.runtime.launcher import ObserverSpec

    t0 = time.monotonic()
    res = launch(scenario(), tmp_path / "run", specs=fakes.specs(), console_log=False,
                 observers=[ObserverSpec("stopped", "cosim.testing.fakes:observe", {"stop_self": True}),
                            ObserverSpec("idle", "cosim.testing.fakes:observe")])
    assert res.completed and time.monotonic() - t0 < promised(15, 60)
    from test_runtime_ring import children_of

    assert not children_of(os.getpid())


def test_a_killed_recorder_is_one_line_not_a_traceback(tmp_path, shm_clean, capfd):
    res = launch(scenario(), tmp_path / "run", specs=fakes.specs(), console_log=True,
                 sinks=[_faulty_recording(2, signal.SIGKILL)])
    _check_ran_without_its_recording(res, "the recorder process ended (exit -9)")
    err = capfd.readouterr().err
    assert "Traceback" not in err and "BrokenPipeError" not in err
    assert "the recorder process ended (exit -9)" in (tmp_path / "run" / "log.txt").read_text()


KILL_SCRIPT = textwrap.dedent("""
    import sys
    sys.path[:0] = [{repo!r}, {tests!r}]
    from cosim.testing import fakes
    from cosim.scenario.config import Scenario
    from cosim.runtime.launcher import launch
    if __name__ == "__main__":
        sc = Scenario(format_version=1, duration_s=3600.0, renderer="mock")
        launch(sc, {out!r}, specs=fakes.specs(), console_log=False)
""")


def _frames_on_disk(path: Path) -> list[int]:
    lines = path.read_text().splitlines()
    width = len(lines[0].split(","))
    assert all(len(line.split(",")) == width for line in lines[1:]), "a half row was left"
    return [int(line.split(",", 1)[0]) for line in lines[1:]]


def test_kill9_of_the_launcher_leaves_the_rows_and_a_running_summary(tmp_path):
    out = tmp_path / "run"
    script = tmp_path / "run_it.py"
    script.write_text(KILL_SCRIPT.format(repo=str(REPO), tests=str(REPO / "tests"), out=str(out)))
    proc = subprocess.Popen([sys.executable, str(script)])
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:  # two blocks of rows appended
            time.sleep(0.1)
            ts = out / "timeseries.csv"
            if ts.exists() and ts.read_text().count("\n") > 1 and time.monotonic() - ts.stat().st_mtime < 5:
                time.sleep(stream.BLOCK_S * 1.5)
                break
        proc.kill()
        proc.wait(10)
    finally:
        proc.kill()
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "running" and summary["completed"] is False
    frames = _frames_on_disk(out / "timeseries.csv")
    assert len(frames) > 1 and frames == list(range(len(frames)))
    # the children follow their launcher (PR_SET_PDEATHSIG) and its resource tracker unlinks (slower when busy)
    deadline = time.monotonic() + promised(1.0, 10.0)
    while list(Path("/dev/shm").glob(f"cosim-{proc.pid}-*")) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not list(Path("/dev/shm").glob(f"cosim-{proc.pid}-*"))


@pytest.fixture
def small_tmpfs(tmp_path, request):
    """A small tmpfs (48 KiB, or ``@pytest.mark.tmpfs_size("128k")``; root and a kernel that allows the mount),
    else the test is skipped."""
    mnt = tmp_path / "small"
    mnt.mkdir()
    size = getattr(request.node.get_closest_marker("tmpfs_size"), "args", ("48k",))[0]
    if subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(mnt)],
                      capture_output=True).returncode:
        pytest.skip("cannot mount a small tmpfs here (needs root)")
    yield mnt
    subprocess.run(["umount", "-l", str(mnt)], check=False)


def _check_full_disk_run(res, run_dir: Path) -> None:
    assert res.exit_code == EXIT_RUN_ERROR
    assert isinstance(res.error, OutputError)
    assert str(res.error).startswith("no space left on device writing ") and "timeseries.csv" in str(res.error)
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["completed"] is False and summary["error"]["type"] == "OutputError"
    frames = _frames_on_disk(run_dir / "timeseries.csv")
    assert frames == list(range(len(frames)))


def test_a_full_disk_is_named_and_keeps_the_summary(small_tmpfs, shm_clean, capfd):
    res = launch(scenario(duration_s=300.0), small_tmpfs / "run", specs=fakes.specs(), console_log=True)
    _check_full_disk_run(res, small_tmpfs / "run")
    assert "Traceback" not in capfd.readouterr().err


def test_an_injected_enospc_at_the_rows_is_named(tmp_path, shm_clean, monkeypatch):
    """The same without a mount: the third block of rows hits ENOSPC after half of it is written."""

    class Full:
        def __init__(self, f):
            self._f, self.writes = f, 0

        def write(self, text):
            self.writes += 1
            if self.writes == 3:
                self._f.write(text[: len(text) // 2])
                self._f.flush()
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
            return self._f.write(text)

        def __getattr__(self, name):
            return getattr(self._f, name)

    real_open = open
    monkeypatch.setattr(stream, "open", lambda *a, **k: Full(real_open(*a, **k)), raising=False)
    monkeypatch.setattr(stream, "BLOCK_S", 0.0)
    res = launch(scenario(duration_s=3.0), tmp_path / "run", specs=fakes.specs(), console_log=False)
    _check_full_disk_run(res, tmp_path / "run")


def _check_ran_without_its_recording(res, why: str) -> None:
    """Every frame ran and every other output is written, but the recording asked for is not whole: the run's
    error (process recorder, exit 1), never a silent completed run."""
    assert res.exit_code == EXIT_RUN_ERROR and not res.completed
    assert isinstance(res.error, RecordingFailed) and res.error.process == "recorder" and why in str(res.error)
    summary = json.loads((res.run_dir / "summary.json").read_text())
    assert summary["frames"] == summary["frames_planned"] and summary["status"] == "failed"
    assert summary["error"]["type"] == "RecordingFailed" and summary["error"]["process"] == "recorder"
    assert len((res.run_dir / "timeseries.csv").read_text().splitlines()) == 1 + summary["frames"]


def test_a_full_disk_under_the_recording_stops_only_the_recording(small_tmpfs, tmp_path, shm_clean, capfd):
    sink = mcap_sink(RecordOptions(path=small_tmpfs / "big.mcap", queue_frames=4, image_every=1))
    res = launch(scenario(duration_s=20.0), tmp_path / "run", specs=fakes.specs(), console_log=True, sinks=[sink])
    _check_ran_without_its_recording(res, "write error")
    err = capfd.readouterr().err
    assert "Traceback" not in err and "no space left on device writing" in err


def test_out_must_be_a_usable_directory(tmp_path):
    f = tmp_path / "a_file"
    f.write_text("")
    with pytest.raises(RunDirError, match="exists and is not a directory"):
        launch(scenario(), f, specs=fakes.specs(), console_log=False)
    with pytest.raises(RunDirError, match="cannot create the directory: Not a directory"):
        launch(scenario(), f / "run", specs=fakes.specs(), console_log=False)


def test_an_unwritable_out_is_refused(tmp_path, monkeypatch):
    """Root may write anywhere: the permission the kernel would refuse a user is injected."""
    from cosim.runtime import files

    monkeypatch.setattr(files.os, "access", lambda path, mode: False)
    with pytest.raises(RunDirError, match=r"--out .*run: permission denied \(the directory is not writable\)"):
        launch(scenario(), tmp_path / "run", specs=fakes.specs(), console_log=False)


def test_a_second_run_on_the_same_out_is_refused(tmp_path, shm_clean):
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    with open(run_dir / LOCK_NAME, "w") as held:
        fcntl.flock(held, fcntl.LOCK_EX)
        held.write("4242\n")
        held.flush()
        with pytest.raises(RunDirError, match=r"another run is writing there \(launcher pid 4242\)"):
            launch(scenario(), run_dir, specs=fakes.specs(), console_log=False)
    assert not (run_dir / "summary.json").exists()
    res = launch(scenario(), run_dir, specs=fakes.specs(), console_log=False)  # free again
    assert res.completed and not (run_dir / LOCK_NAME).exists()


def test_cli_out_errors_exit_2_with_a_message(tmp_path, capsys):
    from cosim.cli import main

    f = tmp_path / "a_file"
    f.write_text("")
    assert main(["run", "default", "--renderer", "none", "--feedback", "ground_truth", "--out", str(f)]) == 2
    err = capsys.readouterr().err
    assert "is not a directory" in err and "nothing was started" in err


def test_process_state_reads_stopped():
    proc = subprocess.Popen(["sleep", "30"])
    try:
        deadline = time.monotonic() + 5      # a process being exec'd may show D (disk sleep) for a moment
        while process_state(proc.pid) not in ("S", "R") and time.monotonic() < deadline:
            time.sleep(0.01)
        state = process_state(proc.pid)
        assert state in ("S", "R"), f"state {state!r} before SIGSTOP"
        os.kill(proc.pid, signal.SIGSTOP)
        deadline = time.monotonic() + 5
        while process_state(proc.pid) != "T" and time.monotonic() < deadline:
            time.sleep(0.01)
        state = process_state(proc.pid)
        assert state == "T", f"state {state!r} after SIGSTOP"
    finally:
        proc.kill()
        proc.wait()
    state = process_state(proc.pid)
    assert state == "", f"state {state!r} after the process was reaped"


def test_one_seed_twice_gives_byte_identical_outputs(tmp_path, shm_clean):
    """Real participants (mock renderer, perception feedback): the timeseries, maps and summary (less its
    wall-clock fields) are byte for byte the same; the wall-clock columns are in timing.csv."""
    sc = Scenario(format_version=1, duration_s=0.5, renderer="mock")
    sc = sc.model_copy(update={"outputs": sc.outputs.model_copy(update={"figures": False})})
    runs = [launch(sc, tmp_path / n, console_log=False) for n in ("a", "b")]
    assert all(r.completed for r in runs)
    a, b = tmp_path / "a", tmp_path / "b"
    for name in ("timeseries.csv", "heightmap_truth.npy", "heightmap_perceived.npy"):
        assert (a / name).read_bytes() == (b / name).read_bytes(), name
    header = (a / "timeseries.csv").read_text().splitlines()[0].split(",")
    timing = (a / "timing.csv").read_text().splitlines()[0].split(",")
    assert not [c for c in header if c.endswith("_ms")]
    assert "perc_state.perception_ms" in timing and timing[0] == "frame"
    assert len((a / "timing.csv").read_text().splitlines()) == len((a / "timeseries.csv").read_text().splitlines())

    def stable(d):
        s = json.loads((d / "summary.json").read_text())
        for k in ("wall_time_s", "real_time_factor", "written_utc", "timing_ms", "ring"):
            s.pop(k, None)
        s.get("perception", {}).pop("timing_ms", None)
        return s

    assert stable(a) == stable(b)
    assert np.load(a / "heightmap_truth.npy").shape == np.load(b / "heightmap_truth.npy").shape


def _cli_run(out: Path, duration_s: float = 3600.0) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, str(REPO / "launch.py"), "run", "default", "--renderer", "none",
                             "--feedback", "ground_truth", "--duration", str(duration_s), "--quiet", "--out", str(out)],
                            cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _wait_for(pred, timeout_s=60.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not pred():
        assert time.monotonic() < deadline, "the run never got there"
        time.sleep(0.01)


def _frames_done(out: Path) -> int:
    ts = out / "timeseries.csv"
    return ts.read_text().count("\n") - 1 if ts.exists() else -1


def _catches(pid: int, sig: int) -> bool:
    """Whether process ``pid`` has a handler for ``sig`` (the SigCgt mask of /proc/PID/status)."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return False
    mask = next((int(line.split()[1], 16) for line in status.splitlines() if line.startswith("SigCgt:")), 0)
    return bool(mask >> (int(sig) - 1) & 1)


def _summary_status(out: Path) -> str:
    try:
        return json.loads((out / "summary.json").read_text())["status"]
    except (OSError, ValueError, KeyError):
        return ""


@pytest.mark.parametrize("moment", ["interpreter", "set-up", "children starting", "running", "figures"])
def test_any_number_of_signals_at_any_moment_exit_130_without_traceback(moment, tmp_path):
    """Three SIGINT/SIGTERM 50 ms apart: exit 130, no traceback, and (once the run directory exists) a summary
    that says the run did not complete, with the frames on disk up to the last one recorded; while the figures
    are drawn, the run's summary stays completed and the figures are cut short."""
    out = tmp_path / "run"
    proc = _cli_run(out, 2.0 if moment == "figures" else 3600.0)
    if moment == "figures":  # the final summary is written just before the figures are drawn
        _wait_for(lambda: _summary_status(out) == "completed" or proc.poll() is not None)
        if proc.poll() is not None:
            pytest.skip("the figures were done before the signal could be sent")
    elif moment == "interpreter":
        # the imports of the CLI: the entry's own handlers are installed (SIGTERM caught: Python's start-up catches
        # only SIGINT), the run's are not yet. A signal before that lands in the interpreter's own start-up, which
        # no program can guard; the moment is found by the handler, not by a sleep (a busy machine starts late)
        _wait_for(lambda: _catches(proc.pid, signal.SIGTERM) or proc.poll() is not None)
    elif moment == "set-up":
        _wait_for(lambda: (out / "scenario.yaml").exists())
    elif moment == "children starting":
        _wait_for(lambda: (out / "run.json").exists())
    else:
        _wait_for(lambda: _frames_done(out) > 0)
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGINT):
        proc.send_signal(sig)
        time.sleep(0.05)
    stdout, stderr = proc.communicate(timeout=30)
    assert proc.returncode == 130, stderr
    assert "Traceback" not in stderr and "Traceback" not in stdout
    if moment == "figures":
        summary = json.loads((out / "summary.json").read_text())
        assert summary["status"] == "completed" and "figures not drawn: stopped by SIGINT" in stderr
        assert summary["figures"] == {"status": "not_drawn", "reason": "stopped by SIGINT while drawing them",
                                      "command": f"python launch.py report {out}"}
    elif (out / "summary.json").exists():
        summary = json.loads((out / "summary.json").read_text())
        assert summary["completed"] is False and summary["status"] in ("interrupted", "running")
        if moment == "running":
            assert summary["status"] == "interrupted" and "stopped by SIGINT" in summary["error"]["message"]
            assert _frames_on_disk(out / "timeseries.csv") == list(range(summary["frames"]))
    if moment == "running":
        assert not list(Path("/dev/shm").glob(f"cosim-{proc.pid}-*"))


@pytest.mark.parametrize("delay_s", [0.0, 0.03, 0.1])
def test_a_signal_after_the_summary_is_printed_still_exits_130(delay_s, tmp_path):
    """SIGTERM while the process ends (after the summary is printed): 130, or 0 when it came after the end;
    never killed by it (143, -15) and no traceback."""
    proc = subprocess.Popen([sys.executable, str(REPO / "launch.py"), "run", "default", "--renderer", "none",
                             "--feedback", "ground_truth", "--duration", "0.5", "--quiet", "--out",
                             str(tmp_path / "run")], cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env={**os.environ, "PYTHONUNBUFFERED": "1"})
    lines = []
    while not any(line.startswith("outcome") for line in lines):  # the summary's last line
        lines.append(proc.stdout.readline())
        assert lines[-1] or proc.poll() is None, lines
    time.sleep(delay_s)
    proc.send_signal(signal.SIGTERM)
    stdout, stderr = proc.communicate(timeout=30)
    assert proc.returncode in (130, 0), (proc.returncode, stderr)
    assert "Traceback" not in stderr


def test_stop_signals_are_idempotent_and_cut_only_optional_work():
    from cosim.errors import RunInterrupted
    from cosim.runtime.signals import StopSignals

    stop = StopSignals()
    stop.check(3)  # nothing yet
    with stop.raising():
        with pytest.raises(RunInterrupted, match="^stopped by SIGTERM$"):
            stop(signal.SIGTERM, None)
        stop(signal.SIGINT, None)  # a second signal inside is only counted
    stop(signal.SIGINT, None)
    assert stop.count == 3 and stop.name == "SIGTERM"
    with pytest.raises(RunInterrupted, match="^stopped by SIGTERM$"):  # optional work after a signal: not begun
        with stop.raising():
            pytest.fail("entered")
    with pytest.raises(RunInterrupted, match="stopped by SIGTERM at frame 7"):
        stop.check(7)


def test_a_failed_row_block_is_cut_back_even_when_the_close_writes_the_rest(tmp_path, monkeypatch):
    """ENOSPC midway through a flush, then the close's retry of the buffered rest succeeds (the cut freed space,
    or another process did): the file still ends at the last whole row, with no gap or half row after it."""

    class HalfThenRest:
        def __init__(self, f):
            self._f, self._pending, self.flushes = f, "", 0

        def write(self, text):
            self._pending += text
            return len(text)

        def flush(self):
            self.flushes += 1
            text, self._pending = self._pending, ""
            if self.flushes == 2:                      # the first row block: half written, then the disk is full
                self._f.write(text[: len(text) // 2])
                self._f.flush()
                self._pending = text[len(text) // 2:]
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
            self._f.write(text)
            self._f.flush()

        def close(self):
            self._f.write(self._pending)           # the retry succeeds
            self._f.close()

        def tell(self):
            return self._f.tell()

    real_open = open
    monkeypatch.setattr(stream, "open", lambda *a, **k: HalfThenRest(real_open(*a, **k)), raising=False)
    path = tmp_path / "rows.csv"
    app = stream._Appender(path, "a,b\n")
    with pytest.raises(OutputError, match="no space left on device writing"):
        app.append("1,2\n3,4\n5,6\n")
    assert path.read_text() == "a,b\n"


def test_a_full_disk_while_the_figures_are_drawn_is_named_and_leaves_no_half_file(tmp_path, shm_clean, capfd,
                                                                                   monkeypatch):
    """ENOSPC halfway through the second figure: exit 1, named with its path in the result and the summary, the
    first figure whole, no half or temporary file, the summary's figures entry says what happened."""
    from cosim.runtime import files

    real_open = open
    target = ".fig8_heightmaps.png.tmp"

    class Full:
        def __init__(self, f):
            self._f = f

        def write(self, data):
            self._f.write(data[: len(data) // 2])
            self._f.flush()
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self._f.close()

    monkeypatch.setattr(files, "open", lambda p, *a, **k: Full(real_open(p, *a, **k)) if str(p).endswith(target)
                        else real_open(p, *a, **k), raising=False)
    sc = Scenario(format_version=1, duration_s=0.5, renderer="none", feedback="ground_truth")
    run_dir = tmp_path / "run"
    res = launch(sc, run_dir, console_log=True)
    assert res.exit_code == EXIT_RUN_ERROR and isinstance(res.error, OutputError)
    assert str(res.error) == f"no space left on device writing {run_dir / 'fig8_heightmaps.png'}"
    names = {p.name for p in run_dir.iterdir()}
    assert "fig7_fullness.png" in names and not names & {"fig8_heightmaps.png", target, "fig9_auger.png"}
    assert (run_dir / "fig7_fullness.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["status"] == "failed" and summary["completed"] is False
    assert summary["error"]["type"] == "OutputError" and summary["error"]["process"] == "supervisor"
    assert summary["figures"] == {"status": "failed", "error": str(res.error)}
    assert summary["frames"] == summary["frames_planned"]  # the simulation itself completed
    assert "Traceback" not in capfd.readouterr().err


@pytest.mark.tmpfs_size("128k")
def test_a_disk_that_fills_while_the_figures_are_drawn(small_tmpfs, shm_clean, capfd):
    """The same on a real 128 KiB file system: the data fits, the figures do not."""
    sc = Scenario(format_version=1, duration_s=0.5, renderer="none", feedback="ground_truth")
    run_dir = small_tmpfs / "run"
    res = launch(sc, run_dir, console_log=True)
    assert res.exit_code == EXIT_RUN_ERROR and isinstance(res.error, OutputError)
    assert str(res.error).startswith(f"no space left on device writing {run_dir}/fig")
    pngs = sorted(run_dir.glob("*.png"))
    assert not list(run_dir.glob(".*.tmp")) and len(pngs) < 4
    assert all(p.read_bytes().endswith(b"IEND\xaeB`\x82") for p in pngs)  # whole files only
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["status"] == "failed" and summary["error"]["message"] == str(res.error)
    assert summary["figures"]["status"] == "failed"
    assert "Traceback" not in capfd.readouterr().err


@pytest.mark.parametrize("where", ["main", "run_cli", "exit functions"])
def test_a_stop_signal_in_the_entrys_last_instructions_is_never_a_traceback(where, tmp_path):
    """The windows the timing test above can only hit by chance, hit every time: a SIGTERM sent as
    ``cosim.cli.main`` returns or as ``run_cli`` returns (a profile hook sends it on the function's return event,
    so the handler runs in the caller's next instructions), or while the exit functions run: 130, no traceback."""
    script = tmp_path / "entry.py"
    script.write_text(textwrap.dedent(f"""
        import os, signal, sys
        sys.path.insert(0, {str(REPO)!r})
        import cosim.cli, cosim.entry
        where = {where!r}

        def main():
            return 0

        def on_return(frame, event, arg):
            if event == "return" and frame.f_code.co_name == where:
                sys.setprofile(None)
                os.kill(os.getpid(), signal.SIGTERM)

        cosim.cli.main = main
        real_exitfuncs = cosim.entry.atexit._run_exitfuncs

        def exitfuncs():
            if where == "exit functions":
                os.kill(os.getpid(), signal.SIGTERM)
            real_exitfuncs()

        cosim.entry.atexit._run_exitfuncs = exitfuncs
        sys.argv = ["launch.py", "list"]
        if where != "exit functions":
            sys.setprofile(on_return)
        cosim.entry.exit_cli()
    """))
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=60)
    assert out.returncode == 130, (out.returncode, out.stderr)
    assert "Traceback" not in out.stderr
