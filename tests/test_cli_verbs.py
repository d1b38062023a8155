"""Every verb the README shows answers its own --help through launch.py, ``python -m cosim`` and the
``graincosim`` entry point; the cheap ones run for real; a typo suggests the name meant; a busy viewer port is a
one-line error before anything starts; the viewer's address is printed only once it answers."""
from __future__ import annotations

import io
import re
import socket
import subprocess
import sys
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path

import pytest
import tomllib

from cosim.cli import VERBS, main
from cosim.scenario.loader import describe_packaged, load_scenario, packaged_scenarios, resolve_scenario_arg
from cosim.viewer.viewinfo import ViewInfo

ROOT = Path(__file__).resolve().parent.parent
#: a verb shown in the docs: "launch.py <verb>" or "python -m cosim <verb>"
_VERB = re.compile(r"(?:launch\.py|python -m cosim)\s+([a-z]+(?:-[a-z]+)*)\b")


def documented_verbs() -> set[str]:
    text = (ROOT / "README.md").read_text() + "".join(p.read_text() for p in (ROOT / "docs").glob("*.md"))
    return {m.group(1) for m in _VERB.finditer(text)}


def call(argv) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with redirect_stdout(out), redirect_stderr(err):
        try:
            code = main(argv)
        except SystemExit as exc:
            code = exc.code
    return code, out.getvalue(), err.getvalue()


def test_the_readme_shows_the_verbs_and_each_is_one():
    verbs = documented_verbs()
    assert {"run", "validate", "schema", "compare", "study", "view", "replay", "list"} <= verbs
    assert verbs <= set(VERBS), f"the README shows verbs the CLI lacks: {verbs - set(VERBS)}"


@pytest.mark.parametrize("verb", sorted(documented_verbs()))
def test_each_documented_verb_has_its_own_help(verb):
    code, out, _ = call([verb, "--help"])
    assert code == 0
    assert out.startswith(f"usage: launch.py {verb} "), out[:200]


@pytest.mark.parametrize("how", [[sys.executable, "launch.py"], [sys.executable, "-m", "cosim"]])
def test_view_and_replay_help_through_launch_py_and_python_m(how):
    for verb, arg in (("view", "run"), ("replay", "file")):
        r = subprocess.run([*how, verb, "--help"], cwd=ROOT, capture_output=True, text=True, timeout=60)
        assert r.returncode == 0, r.stderr
        assert r.stdout.startswith(f"usage: launch.py {verb} ") and arg in r.stdout and "--port" in r.stdout


def test_the_console_script_is_the_same_entry_point():
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    assert scripts["graincosim"] == "cosim.entry:exit_cli"


def test_list_prints_every_packaged_scenario_with_its_description():
    code, out, _ = call(["list"])
    assert code == 0
    rows = dict(re.split(r"\s{2,}", line.strip(), maxsplit=1) for line in out.strip().splitlines())
    assert set(rows) == set(packaged_scenarios())
    descriptions = describe_packaged()
    assert all(descriptions[n] and rows[n] == descriptions[n] for n in rows)
    assert rows["heavy_noise"] == "5 cm range noise and 30 % dropout."


def test_validate_and_schema_run_for_real(tmp_path):
    code, out, _ = call(["validate", "default"])
    assert code == 0 and out.startswith("default: valid (")
    code, _, _ = call(["schema", "--out", str(tmp_path / "s.json")])
    assert code == 0
    assert (tmp_path / "s.json").read_text() == (ROOT / "cosim/schema/scenario.schema.json").read_text()


def test_a_short_run_runs_for_real_and_quiet_means_no_progress(tmp_path, shm_clean):
    code, out, err = call(["run", "default", "--renderer", "none", "--feedback", "ground_truth", "--duration", "1",
                           "--out", str(tmp_path / "r"), "--quiet"])
    assert code == 0, err
    assert "completed: True" in out and "frame" not in err
    assert (tmp_path / "r" / "summary.json").exists()


def test_a_misspelt_scenario_name_suggests_the_one_meant(tmp_path):
    code, _, err = call(["run", "defualt", "--out", str(tmp_path / "r")])
    assert code == 2
    assert "did you mean 'default'?" in err and "nothing was started" in err
    assert not (tmp_path / "r").exists()
    code, _, err = call(["validate", "hevy_noise"])
    assert code == 2 and "did you mean 'heavy_noise'?" in err


@pytest.fixture
def busy_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        yield s.getsockname()[1]


def test_a_busy_viewer_port_is_one_line_before_anything_starts(tmp_path, busy_port, shm_clean):
    code, out, err = call(["run", "default", "--renderer", "mock", "--duration", "1", "--viewer",
                           "--viewer-port", str(busy_port), "--out", str(tmp_path / "r"), "--quiet"])
    assert code == 2
    assert err.count("\n") == 1 and f"viewer cannot listen on 127.0.0.1:{busy_port}" in err, err
    assert "nothing was started" in err and out == ""
    assert not (tmp_path / "r").exists()


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    import test_viewer_standins as standins

    from cosim.recording import mcap_sink
    from cosim.runtime.launcher import launch

    out = tmp_path_factory.mktemp("replay") / "run"
    res = launch(standins.scenario(0.5), out, specs=standins.specs(), console_log=False, sinks=[mcap_sink()])
    assert res.completed
    return out / "recording.mcap"


def test_replay_on_a_busy_port_exits_2_with_one_message(recording, busy_port):
    rec = recording
    r = subprocess.run([sys.executable, "launch.py", "replay", str(rec), "--port", str(busy_port)], cwd=ROOT,
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2
    assert f"viewer cannot listen on 127.0.0.1:{busy_port}" in r.stderr
    assert "Traceback" not in r.stderr and "BufferError" not in r.stderr


def test_the_viewer_address_is_printed_only_once_it_answers(recording):
    """The announcer waits for the announce file, then for /healthz: a server that listens but does not answer
    yet is not announced; the address printed is the one the server got (port 0)."""
    import json
    import threading
    import time

    from cosim.viewer.address import ViewerAnnouncer
    from cosim.viewer.replay import ReplaySource
    from cosim.viewer.server import DashboardServer

    stream = io.StringIO()
    announcer = ViewerAnnouncer(stream)
    srv = DashboardServer(ReplaySource(recording), port=0)  # bound and listening, not answering yet
    try:
        announcer.path.write_text(json.dumps({"url": srv.url}))
        time.sleep(1.5)
        assert stream.getvalue() == "", "announced before the server answered"
        threading.Thread(target=srv.serve_forever, kwargs={"poll_interval": 0.1}, daemon=True).start()
        deadline = time.monotonic() + 20
        while not stream.getvalue() and time.monotonic() < deadline:
            time.sleep(0.05)
        assert stream.getvalue() == f"viewer: {srv.url} (while the run lasts)\n"
        assert srv.server_port != 0 and f":{srv.server_port}/" in announcer.url
    finally:
        announcer.close()
        srv.shutdown()
        srv.server_close()
    assert not announcer.path.exists()


def test_run_hands_the_viewer_its_host_port_announce_file_and_the_scenarios_view():
    from cosim.cli import build_parser, run_extras

    args = build_parser().parse_args(["run", "default", "--viewer", "--viewer-port", "0", "--viewer-host",
                                      "127.0.0.2"])
    args.viewer_announce = "/tmp/x.json"
    sc = load_scenario(resolve_scenario_arg("default"))
    (obs,), sinks = run_extras(args, sc)
    assert obs.target == "cosim.viewer.server:observe" and sinks == []
    assert dict(obs.kwargs) == {"port": 0, "host": "127.0.0.2", "announce": "/tmp/x.json",
                                "view": ViewInfo.of(sc).to_dict()}
    assert ViewInfo.from_dict(obs.kwargs["view"]).size_m == (sc.cart.interior_length_m, sc.cart.interior_width_m)


def test_main_in_process_leaves_the_signal_handlers_as_found(monkeypatch):
    """``main`` called from a program (a test, a notebook, a pool worker) that ends on a stop must not leave
    SIGINT/SIGTERM ignored: a process pool's workers inherit ignored signals and then never terminate."""
    import signal

    import cosim.cli as cli

    def stopped(args):
        raise KeyboardInterrupt

    monkeypatch.setattr(cli, "_load", stopped)
    before = signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)
    with redirect_stderr(io.StringIO()) as err:
        assert main(["validate", "default"]) == 130
    assert "interrupted" in err.getvalue()
    assert (signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)) == before


def test_export_is_export_fmu(tmp_path):
    """``launch.py export`` is the same verb as ``export-fmu`` (its help, its refusals)."""
    code, out, _ = call(["export", "--help"])
    assert code == 0 and "--fmi" in out and out == call(["export-fmu", "--help"])[1]
    code, _, err = call(["export", "default"])
    assert code == 2 and "--out" in err

