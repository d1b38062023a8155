"""``view`` and ``replay`` end with exit 130 on Ctrl-C or SIGTERM, as every verb does, and a viewer asked to attach to
a run that has ended suggests replaying a recording only when one was written."""
from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import pytest

from cosim.viewer.live import RECORDING_NAME, RunEnded, resolve_run

ROOT = Path(__file__).resolve().parent.parent
STARTUP_S = 120.0


def _ended_run(tmp_path: Path, recording: bytes | None) -> Path:
    run = tmp_path / "run"
    run.mkdir()
    (run / "run.json").write_text(json.dumps({"segment": "graincosim-gone", "ended": True}))
    if recording is not None:
        (run / RECORDING_NAME).write_bytes(recording)
    return run


@pytest.mark.parametrize("recording, suggests", [(None, False), (b"", False), (b"\x89MCAP0\r\n...", True)])
def test_an_ended_run_suggests_a_replay_only_of_a_recording_that_was_written(tmp_path, recording, suggests):
    run = _ended_run(tmp_path, recording)
    with pytest.raises(RunEnded, match=r"run run has ended \(its segment graincosim-gone is gone\)") as info:
        resolve_run(run)
    message = str(info.value)
    assert ("replay" in message and str(run / RECORDING_NAME) in message) == suggests, message
    assert suggests or "no recording was written: `launch.py run --record` writes one" in message


def test_the_recording_name_is_the_writers():
    pytest.importorskip("foxglove", reason="recording needs foxglove-sdk")
    from cosim.recording.writer import DEFAULT_NAME

    assert RECORDING_NAME == DEFAULT_NAME


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> Path:
    pytest.importorskip("foxglove", reason="recording needs foxglove-sdk")
    out = tmp_path_factory.mktemp("rec") / "run"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    r = subprocess.run([sys.executable, str(ROOT / "launch.py"), "run", "default", "--renderer", "none", "--feedback",
                        "ground_truth", "--duration", "0.5", "--record", "--quiet", "--set", "outputs.figures=false",
                        "--out", str(out)], env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    return out / RECORDING_NAME


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.parametrize("how, sig", [("launch.py replay", signal.SIGINT), ("launch.py replay", signal.SIGTERM),
                                      ("python -m cosim.viewer", signal.SIGINT)])
def test_replay_ends_with_130_on_ctrl_c_and_sigterm(recording, how, sig):
    port = _free_port()
    cmd = ([sys.executable, str(ROOT / "launch.py"), "replay", str(recording)] if how.startswith("launch") else
           [sys.executable, "-m", "cosim.viewer", "--replay", str(recording)]) + ["--port", str(port)]
    proc = subprocess.Popen(cmd, env={**os.environ, "PYTHONPATH": str(ROOT)}, cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + STARTUP_S
        while True:
            assert proc.poll() is None, proc.communicate()
            try:
                urllib.request.urlopen(f"http://127.0.0.1:{port}/healthz", timeout=2).read()
                break
            except OSError:
                assert time.monotonic() < deadline, "the replay server did not start"
                time.sleep(0.1)
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=30)
        assert proc.returncode == 130, err
        assert "Traceback" not in err and err.rstrip().endswith("interrupted")
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
