"""``launch.py sweep``: sweep files validated whole, runs on a LocalCluster and on a scheduler with workers,
resume, failures, the results table."""
from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from cosim.cli import main
from cosim.errors import ScenarioError
from cosim.runtime.launcher import launch
from cosim.studies.results import METRICS
from cosim.studies.sweep import run_sweep
from cosim.studies.sweepfile import load_sweep

distributed = pytest.importorskip("distributed")

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / "docs" / "examples" / "strategies_sweep.yaml"
SHM = Path("/dev/shm")


def _rows(out: Path) -> dict[str, dict]:
    with open(out / "results.csv", newline="") as f:
        return {r["id"]: r for r in csv.DictReader(f)}


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


def _assert_gone(pids) -> None:
    deadline = time.monotonic() + 20
    while any(map(_alive, pids)) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not [p for p in pids if _alive(p)], "worker processes still running"


def _assert_nothing_left(out: Path, workers_closed: bool = True) -> None:
    """Every run's segment is gone and (once the cluster is closed) every process that launched one has ended."""
    infos = [json.loads(p.read_text()) for p in (out / "runs").glob("*/run.json")]
    assert infos
    for info in infos:
        assert info["ended"] is True
        assert not (SHM / info["segment"]).exists(), info["segment"]
    if workers_closed:
        _assert_gone({info["launcher_pid"] for info in infos})


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "sweep.yaml"
    path.write_text(text)
    return path


# ------------------------------------------------------------------------------------------- sweep files
HEAD = "format_version: 1\nset: {renderer: none, feedback: ground_truth, duration_s: 5.0}\n"


@pytest.mark.parametrize("body, where", [
    ("grid:\n  controller.stratgy: [front_to_back, lowest_first]\n",
     r"sweep.yaml:4:3: grid.controller.stratgy: unknown key 'stratgy' in 'controller' \(did you mean 'strategy'\?\)"),
    ("grid:\n  timing.latency_frames: [1, '2']\n", r"sweep.yaml:4:30: grid.timing.latency_frames\[1\]: Input "
     r"should be a valid integer, got '2'"),
    ("grid:\n  timing.sensor_period_s: [0.1, -0.1]\n", r"sweep.yaml:4:33: grid.timing.sensor_period_s\[1\]: Input "
     r"should be greater than 0 s, got -0.1 s"),
    ("zip:\n  combine.speed_mps: [1.0, 1.5]\n  timing.latency_frames: [1]\n", r"sweep.yaml:5:3: "
     r"zip.timing.latency_frames: zip parameters are varied together, so their lengths must be equal: "
     r"'timing.latency_frames' has 1, 'combine.speed_mps' has 2"),
    ("grid: {controller.strategy: [front_to_back]}\nseed: 3\n", r"sweep.yaml:4:1: seed: unknown key 'seed'"),
    ("random:\n  combine.speed_mps: {distribution: uniform, low: 2.0, high: 1.0, count: 3}\n",
     r"sweep.yaml:4:3: random.combine.speed_mps: low \(2.0\) must be below high \(1.0\)"),
    ("random:\n  combine.speed_mps: {distribution: uniform, low: -3.0, high: -2.0, count: 2}\n",
     r"sweep.yaml:4:3: random.combine.speed_mps \(value -2\.\d+\): Input should be greater than or equal to 0"),
    ("base: nowhere.yaml\n", r"sweep.yaml:3:7: base: no such packaged scenario or file 'nowhere.yaml'"),
])
def test_bad_sweep_files_are_rejected_with_their_lines(tmp_path, body, where):
    with pytest.raises(ScenarioError, match=where):
        load_sweep(_write(tmp_path, HEAD + body))


@pytest.mark.parametrize("body, where", [
    ("seeds: 1000000000000\n", r"sweep.yaml:3:1: seeds: 1,000,000,000,000 seeds: a sweep has at most 100,000 runs"),
    ("grid:\n  combine.speed_mps: [{v}]\n  timing.latency_frames: [{v}]\n",
     r"sweep.yaml:1:1: <root>: 1,000,000 runs: a sweep has at most 100,000"),
    ("random:\n  combine.speed_mps: {{distribution: uniform, low: 1, high: 2, count: 1000000000000}}\n",
     r"random.combine.speed_mps.count: Input should be less than or equal to 100000"),
    ("grid:\n  combine.heading_deg: [.nan, 3]\n", r"sweep.yaml:4:25: grid.combine.heading_deg\[0\]: NaN is not a "
                                                r"finite number"),
    ("grid:\n  combine.heading_deg: [1e308, 3]\n", r"sweep.yaml:4:25: grid.combine.heading_deg\[0\]: 1e\+308 deg "
                                                 r"is above 360 deg"),
    ('name: "a\\eb"\n', r"sweep.yaml:3:7: name: text 'a\\x1bb' holds the control character U\+001B"),
])
def test_sizes_and_hostile_values_are_refused_before_anything_is_expanded(tmp_path, body, where):
    """A count of 10^12 seeds or draws, or a grid of a million points, is refused before a list of that size is
    built; NaN and control characters at their line."""
    t = time.perf_counter()
    with pytest.raises(ScenarioError, match=where):
        load_sweep(_write(tmp_path, HEAD + body.format(v=", ".join(map(str, range(1, 1001))))))
    assert time.perf_counter() - t < 30.0


def test_plugin_modules_beside_the_sweep_file_are_found_with_a_packaged_base(tmp_path):
    (tmp_path / "fill_here.py").write_text("def f(full, height, current):\n    return 0\n")
    runs = load_sweep(_write(tmp_path, HEAD + "base: default\ngrid:\n  controller.strategy: [fill_here:f, "
                                       "front_to_back]\n")).runs
    assert [r.scenario.plugin_dir for r in runs] == [str(tmp_path)] * 2
    # a base file keeps its own folder (its plug-ins live there), unless the sweep sets plugin_dir
    (tmp_path / "scen").mkdir()
    (tmp_path / "scen" / "base.yaml").write_text("format_version: 1\n")
    [run] = load_sweep(_write(tmp_path, HEAD + "base: scen/base.yaml\n")).runs
    assert run.scenario.plugin_dir == str(tmp_path / "scen")


def test_every_problem_is_reported_at_once_and_the_cli_starts_nothing(tmp_path, capsys):
    path = _write(tmp_path, HEAD + "grid:\n  controller.strategy: [front_to_back, sideways]\n"
                  "  grain.cell_m: [0.1, 0.0]\nseeds: [0, 0]\n")
    assert main(["sweep", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "sweep.yaml:6:1: seeds: seeds repeat: [0, 0]" in err
    assert "1 problem(s); nothing was started." in err
    path.write_text(HEAD + "grid:\n  controller.strategy: [front_to_back, sideways]\n  grain.cell_m: [0.1, 0.0]\n")
    assert main(["sweep", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "sweep.yaml:4:40: grid.controller.strategy[1]: " in err and "'sideways'" in err
    assert "sweep.yaml:5:23: grid.grain.cell_m[1]: Input should be greater than 0" in err
    assert "2 problem(s); nothing was started." in err and not (tmp_path / "out").exists()


def test_expansion_counts_ids_and_reproducible_samples(tmp_path):
    text = HEAD + ("grid:\n  controller.strategy: [front_to_back, lowest_first]\n"
                   "zip:\n  combine.speed_mps: [1.0, 1.2, 1.4]\n  timing.latency_frames: [1, 2, 3]\n"
                   "random:\n  sensor.noise.range_sigma_m: {distribution: loguniform, low: 0.001, high: 0.1, "
                   "count: 4}\nseeds: 2\n")
    a, b = load_sweep(_write(tmp_path, text)), load_sweep(tmp_path / "sweep.yaml")
    assert len(a.runs) == 2 * 3 * 4 * 2 and len({r.id for r in a.runs}) == len(a.runs)
    assert [r.id for r in a.runs] == [r.id for r in b.runs]  # stable: resume relies on it
    sigmas = sorted({r.params["sensor.noise.range_sigma_m"] for r in a.runs})
    assert len(sigmas) == 4 and all(0.001 <= s <= 0.1 for s in sigmas)
    for r in a.runs:  # zip moves together; the scenario carries every override and the seed
        assert r.params["timing.latency_frames"] == round((r.params["combine.speed_mps"] - 1.0) / 0.2) + 1
        assert r.scenario.combine.speed_mps == r.params["combine.speed_mps"] and r.scenario.seed == r.seed
        assert r.scenario.sensor.noise.range_sigma_m == r.params["sensor.noise.range_sigma_m"]
        assert r.scenario.duration_s == 5.0 and not r.needs_gl and r.cores == 1
    _write(tmp_path, text.replace("seeds: 2", "seeds: 2\nsample_seed: 1"))
    assert sorted({r.params["sensor.noise.range_sigma_m"] for r in load_sweep(tmp_path / "sweep.yaml").runs}) != sigmas


# ------------------------------------------------------------------------------------------------ runs
@pytest.fixture(scope="module")
def local_sweep(tmp_path_factory):
    """The documented command: the example sweep on an embedded LocalCluster of 2 worker processes."""
    out = tmp_path_factory.mktemp("local")
    assert main(["sweep", str(EXAMPLE), "--jobs", "2", "--out", str(out), "--quiet"]) == 0
    return out


def test_local_sweep_writes_one_row_per_run_with_the_runs_metrics(local_sweep):
    rows = _rows(local_sweep)
    sweep = load_sweep(EXAMPLE)
    assert sorted(rows) == sorted(r.id for r in sweep.runs) and len(rows) == 4
    for run in sweep.runs:
        row = rows[run.id]
        summary = json.loads((local_sweep / "runs" / run.id / "summary.json").read_text())
        assert row["completed"] == "True" and row["error"] == "" and row["attempts"] == "1"
        assert row["controller.strategy"] == run.scenario.controller.strategy
        assert float(row["profile_rmse_m"]) == summary["fill"]["profile_rmse_m"]
        assert float(row["sim_time_s"]) == pytest.approx(10.0)
        assert row["worker"].startswith("tcp://127.0.0.1:")
        assert list(METRICS) == [c for c in row if c in METRICS]
        # whether the job was done, and why (10 s cannot fill the cart: unfinished, neither a success nor a failure)
        assert row["outcome"] == summary["outcome"]["status"] == "unfinished"
        assert row["outcome_reason"] == summary["outcome"]["reason"] and "ended at its duration" in row["outcome_reason"]
    # the strategy changes the outcome: the table is not one run copied four times
    assert len({rows[r.id]["profile_rmse_m"] for r in sweep.runs}) == 4
    # a plain launched run of the same scenario gives the same numbers
    one = sweep.runs[0]
    ref = launch(one.scenario, local_sweep / "reference", console_log=False).summary
    assert float(rows[one.id]["profile_rmse_m"]) == ref["fill"]["profile_rmse_m"]
    assert sorted(p.name for p in local_sweep.glob("sweep_*.png")) == [
        "sweep_fill_fraction.png", "sweep_max_overfill_m.png", "sweep_profile_rmse_m.png",
        "sweep_real_time_factor.png", "sweep_spill_kg.png", "sweep_wall_time_s.png"]
    _assert_nothing_left(local_sweep)


def test_resume_runs_nothing_again(local_sweep, capsys):
    before = {p: p.stat().st_mtime_ns for p in local_sweep.glob("runs/*/summary.json")}
    assert main(["sweep", str(EXAMPLE), "--out", str(local_sweep), "--quiet"]) == 0
    assert "0 failed, 4 finished before" in capsys.readouterr().out
    assert {p: p.stat().st_mtime_ns for p in local_sweep.glob("runs/*/summary.json")} == before
    rows = _rows(local_sweep)
    assert len(rows) == 4 and {r["attempts"] for r in rows.values()} == {"0"}
    assert all(r["worker"].startswith("tcp://127.0.0.1:") and r["completed"] == "True" for r in rows.values())
    # a run without a completed summary (failed, or stopped by Ctrl-C) runs again, and only that one
    gone = sorted(before)[0]
    gone.write_text(gone.read_text().replace('"completed": true', '"completed": false'))
    assert main(["sweep", str(EXAMPLE), "--out", str(local_sweep), "--quiet", "--jobs", "1"]) == 0
    after = {p: p.stat().st_mtime_ns for p in local_sweep.glob("runs/*/summary.json")}
    assert [p for p in after if after[p] != before[p]] == [gone]
    rows = _rows(local_sweep)
    assert sorted(r["attempts"] for r in rows.values()) == ["0", "0", "0", "1"]
    assert rows[gone.parent.name]["completed"] == "True"


@pytest.fixture
def cluster(tmp_path):
    """A scheduler and two workers (nannies, so the workers are daemonic) as subprocesses on 127.0.0.1, started in
    a folder of their own (``tmp_path / "workers"``), as on a user's machines."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), str(ROOT / "tests")])}
    sched_file, pids = tmp_path / "scheduler.json", set()
    workers_cwd = tmp_path / "workers"
    workers_cwd.mkdir()
    cli = [sys.executable, "-m"]
    procs = [subprocess.Popen(cli + ["distributed.cli.dask_scheduler", "--host", "127.0.0.1", "--port", "0",
                                     "--no-dashboard", "--dashboard-address", "127.0.0.1:0",
                                     "--scheduler-file", str(sched_file)], env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    try:
        deadline = time.monotonic() + 60
        while not sched_file.exists() and time.monotonic() < deadline:
            time.sleep(0.2)
        address = json.loads(sched_file.read_text())["address"]
        for _ in range(2):
            procs.append(subprocess.Popen(cli + ["distributed.cli.dask_worker", address, "--nthreads", "1",
                                                 "--host", "127.0.0.1", "--no-dashboard",
                                                 "--dashboard-address", "127.0.0.1:0"], env=env,
                                          cwd=workers_cwd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        with distributed.Client(address) as client:
            client.wait_for_workers(2, timeout=90)
            pids = set(client.run(os.getpid).values())
        yield address
    finally:
        for p in reversed(procs):
            p.terminate()
        for p in reversed(procs):
            try:
                p.wait(30)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
    _assert_gone(pids)


def test_scheduler_and_workers_give_the_same_metrics_per_run(local_sweep, cluster, tmp_path, monkeypatch, capsys):
    """The README's form on a user's cluster: a relative --out, workers started in another folder. The runs land
    in the sweep's folder (results.csv's run_dir, relative to it, points at each), and a second command resumes."""
    sweep = load_sweep(EXAMPLE)
    (tmp_path / "here").mkdir()
    monkeypatch.chdir(tmp_path / "here")
    command = ["sweep", str(EXAMPLE), "--scheduler", cluster, "--out", "remote", "--quiet"]
    assert main(command) == 0
    assert "4/4 runs completed, 0 failed, 0 finished before" in capsys.readouterr().out
    out = tmp_path / "here" / "remote"
    assert not list((tmp_path / "workers").iterdir())  # nothing in the workers' own folder
    for row in _rows(out).values():
        assert row["run_dir"] == f"runs/{row['id']}"
        assert json.loads((out / row["run_dir"] / "summary.json").read_text())["completed"] is True
    assert main(command) == 0
    assert "4/4 runs completed, 0 failed, 4 finished before" in capsys.readouterr().out
    local, remote = _rows(local_sweep), _rows(out)
    assert sorted(local) == sorted(remote)
    for rid in local:
        for col in ("profile_rmse_m", "fill_fraction", "max_overfill_m", "spill_kg", "sim_time_s"):
            assert remote[rid][col] == local[rid][col], (rid, col)
        assert remote[rid]["worker"].startswith("tcp://127.0.0.1:")
    # a GL run has nowhere to go on this cluster: no worker declares EGL
    gl = type(sweep)(sweep.name, sweep.parameters, (sweep.runs[0].__class__(
        "gl-run", {}, 0, sweep.runs[0].scenario.model_copy(update={"renderer": "gl", "feedback": "perception"})),))
    with pytest.raises(RuntimeError, match="no worker of the cluster declares the EGL resource"):
        run_sweep(gl, tmp_path / "gl", scheduler=cluster, quiet=True, figures=False)
    _assert_nothing_left(out, workers_closed=False)  # the fixture checks the workers end


def test_a_failing_run_is_recorded_and_a_dead_worker_costs_only_its_run(tmp_path):
    from sweep_runners import faulty

    _write(tmp_path, HEAD + "grid:\n  controller.strategy: [front_to_back, back_to_front, lowest_first]\n")
    sweep = load_sweep(tmp_path / "sweep.yaml")
    outcome = run_sweep(sweep, tmp_path / "out", jobs=2, quiet=True, runner=faulty, figures=False)
    assert (outcome.total, outcome.completed, outcome.failed) == (3, 2, 1)
    rows = {r["controller.strategy"]: r for r in _rows(tmp_path / "out").values()}
    bad = rows["back_to_front"]
    assert bad["completed"] == "False" and bad["attempts"] == "2"
    assert bad["error"] == "RuntimeError: injected failure for back_to_front" and bad["profile_rmse_m"] == ""
    killed = rows["lowest_first"]  # its first worker died; Dask ran it again elsewhere
    assert killed["completed"] == "True" and killed["error"] == ""
    assert (tmp_path / "out" / "runs" / f"{killed['id']}.killed").exists()
    assert rows["front_to_back"]["completed"] == "True"
    _assert_nothing_left(tmp_path / "out")


def test_the_documented_sweep_files_and_errors(tmp_path, monkeypatch, capsys):
    """docs/sweeps.md: the reference example is valid and expands as said; the bad one gives the errors shown."""
    text = (ROOT / "docs" / "sweeps.md").read_text()
    blocks = text.split("```yaml\n")[1:]
    reference, bad = (b.split("```", 1)[0] for b in blocks[:2])
    sweep = load_sweep(_write(tmp_path, reference))
    assert len(sweep.runs) == 3 * 2 * 3 * 4 * 3
    assert sweep.parameters == ("controller.strategy", "timing.latency_frames", "combine.speed_mps",
                                "machine_sync.initial_long_error_m", "sensor.noise.range_sigma_m", "grain.cell_m")
    assert {r.params["grain.cell_m"] for r in sweep.runs} <= {0.1, 0.05}
    shown = text.split("gives\n\n```text\n", 1)[1].split("```", 1)[0]
    _write(tmp_path, bad)
    monkeypatch.chdir(tmp_path)
    assert main(["sweep", "sweep.yaml"]) == 2
    assert capsys.readouterr().err == shown
    assert not (tmp_path / "runs").exists()


def test_sweep_figures_of_a_group_whose_values_are_identical(tmp_path):
    """Three runs of 0.1 have the float mean 0.10000000000000002, 1 ulp above their max: the error bar's lower
    half came out negative and matplotlib refused it ('yerr' must not contain negative values)."""
    from cosim.studies.figures import spread, write_sweep_figures

    rows = [{"id": f"r{i}", "completed": True, "seed": i, "controller.strategy": "a", "spill_kg": 0.1}
            for i in range(3)]
    rows += [{"id": f"s{i}", "completed": True, "seed": i, "controller.strategy": "b", "spill_kg": 0.7}
             for i in range(3)]
    assert sum([0.1] * 3) / 3 > 0.1 and sum([0.7] * 3) / 3 < 0.7  # the float facts behind it
    assert [(v, mean) for v, mean, *_ in spread(rows, "controller.strategy", "spill_kg")] == [("a", 0.1), ("b", 0.7)]
    assert [p.name for p in write_sweep_figures(tmp_path, rows, ("controller.strategy",))] == ["sweep_spill_kg.png"]


def test_ctrl_c_during_a_sweep_stops_it_in_order_without_tracebacks(tmp_path):
    """Ctrl-C on the terminal reaches the whole foreground process group: the sweep, its Dask workers and the
    runs' children. Only the sweep acts on it (the cluster's processes are born with SIGINT blocked): the runs in
    progress end interrupted with their rows, exit 130, one message, no traceback and no leaked resource."""
    _write(tmp_path, HEAD.replace("duration_s: 5.0", "duration_s: 3600.0")
           + "grid:\n  controller.strategy: [front_to_back, lowest_first]\n")
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, str(ROOT / "launch.py"), "sweep", str(tmp_path / "sweep.yaml"),
                             "--jobs", "2", "--out", str(out), "--quiet"], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while not any(p.stat().st_size > 2000 for p in out.glob("runs/*/timeseries.csv")):
            assert time.monotonic() < deadline and proc.poll() is None, "no run got going"
            time.sleep(0.1)
        os.killpg(proc.pid, signal.SIGINT)  # what a terminal's Ctrl-C does
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 130, stderr
    assert "interrupted: the runs that finished are kept; run the same command to resume" in stderr
    assert "Traceback" not in stderr and "KeyboardInterrupt" not in stderr and "leaked" not in stderr, stderr
    summaries = [json.loads(p.read_text()) for p in out.glob("runs/*/summary.json")]
    assert summaries and all(s["status"] == "interrupted" for s in summaries)  # one may not have begun its frames
    assert any(s["frames"] > 0 for s in summaries)
    _assert_nothing_left(out)


def _patience():
    import dask
    return (dask.config.get("distributed.comm.timeouts.tcp"), dask.config.get("distributed.scheduler.worker-ttl"))


def test_the_embedded_cluster_waits_for_starved_processes_instead_of_cutting_them_off():
    """On a busy machine the embedded cluster's own processes go silent for minutes: the client, the scheduler
    and the workers all carry the patient timeouts (Dask's 30 s TCP timeout cancelled every run of a sweep at
    nice 19 beside ten busy processes), and they end with the sweep (the client's setting is not left behind)."""
    from cosim.studies.sweep import PATIENT_CLUSTER, open_client

    want = (PATIENT_CLUSTER["distributed.comm.timeouts.tcp"], PATIENT_CLUSTER["distributed.scheduler.worker-ttl"])
    before = _patience()
    with open_client(None, 1, gl=False) as client:
        assert _patience() == want                                            # the client
        assert client.run_on_scheduler(_patience) == want                     # the scheduler
        assert list(client.run(_patience).values()) == [want]                 # the worker
    assert _patience() == before
