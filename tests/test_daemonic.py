"""``launch()`` inside daemonic workers: a multiprocessing.Pool worker and a Dask worker."""
from __future__ import annotations

import multiprocessing as mp

import pytest

from cosim.runtime.daemonic import children_allowed
from cosim.scenario.config import Scenario

DURATION_S = 3.0


def _scenario() -> Scenario:
    return Scenario(format_version=1, feedback="ground_truth", renderer="none", duration_s=DURATION_S)


def _noop() -> None:
    pass


def _launch_here(out: str) -> dict:
    """Run in a worker: whether it is daemonic, whether a plain child start is refused there, and the run."""
    from cosim.runtime.launcher import launch

    me = mp.current_process()
    refused = ""
    try:
        mp.get_context("spawn").Process(target=_noop).start()
    except AssertionError as exc:
        refused = str(exc)
    result = launch(_scenario(), __import__("pathlib").Path(out), console_log=False)
    return {"daemon": me.daemon, "daemon_after": me.daemon, "refused": refused, "summary": result.summary,
            "children": result.children}


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    from cosim.runtime.launcher import launch

    return launch(_scenario(), tmp_path_factory.mktemp("ref") / "run", console_log=False).summary


def _check(got: dict, reference: dict) -> None:
    assert got["daemon"] and got["daemon_after"], "the worker should be daemonic before and after the run"
    assert "daemonic processes are not allowed to have children" in got["refused"]
    s = got["summary"]
    assert s["completed"] is True and s["frames"] == round(DURATION_S / 0.1) + 1
    assert got["children"] == {"dynamics": 0}
    # the same deterministic run as one launched from the test process
    assert s["fill"]["section_mean_height_m"] == reference["fill"]["section_mean_height_m"]
    assert s["mass_balance"]["delivered_m3"] == reference["mass_balance"]["delivered_m3"]


def test_children_allowed_lifts_and_restores_the_flag():
    cfg = mp.current_process()._config
    saved = cfg.get("daemon")
    cfg["daemon"] = True
    try:
        with children_allowed():
            assert mp.current_process().daemon is False
            with children_allowed():
                assert mp.current_process().daemon is False
            assert mp.current_process().daemon is False
        assert mp.current_process().daemon is True
    finally:
        cfg["daemon"] = saved


def test_launch_inside_a_pool_worker(tmp_path, reference, shm_clean):
    with mp.get_context("spawn").Pool(1) as pool:
        got = pool.apply(_launch_here, (str(tmp_path / "run"),))
    _check(got, reference)


def test_launch_inside_a_dask_worker(tmp_path, reference, shm_clean):
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address="127.0.0.1:0", scheduler_kwargs={"dashboard": False}) as cluster, \
            distributed.Client(cluster) as client:
        got = client.submit(_launch_here, str(tmp_path / "run"), pure=False).result()
    _check(got, reference)
