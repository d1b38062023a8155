"""Thread pools of the run's processes (cosim.runtime.threadpools): single-threaded BLAS/OpenMP/OpenCV unless the user says."""
from __future__ import annotations

import multiprocessing as mp
import os

import pytest

from cosim.runtime.threadpools import POOL_VARIABLES, default_to_single_threaded_pools, single_threaded_pools


def _report(q) -> None:
    q.put({v: os.environ.get(v) for v in POOL_VARIABLES})


def _report_opencv(q) -> None:
    import cv2

    q.put(cv2.getNumThreads())


def _spawned_env(target=_report):
    ctx = mp.get_context("spawn")
    q = ctx.Queue()
    with single_threaded_pools():
        p = ctx.Process(target=target, args=(q,))
        p.start()
    got = q.get(timeout=30)
    p.join(timeout=30)
    return got


def test_children_get_one_thread_and_the_parent_is_restored(monkeypatch):
    for v in POOL_VARIABLES:
        monkeypatch.delenv(v, raising=False)
    assert _spawned_env() == {v: "1" for v in POOL_VARIABLES}
    assert not any(v in os.environ for v in POOL_VARIABLES)


def test_opencv_in_a_child_runs_one_thread(monkeypatch):
    # the variable is the one OpenCV itself reads at load: the child's pool really has one thread
    for v in POOL_VARIABLES:
        monkeypatch.delenv(v, raising=False)
    assert _spawned_env(_report_opencv) == 1


def test_a_users_setting_is_kept(monkeypatch):
    for v in POOL_VARIABLES:
        monkeypatch.delenv(v, raising=False)
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "2")
    got = _spawned_env()
    assert got["OPENBLAS_NUM_THREADS"] == "2"
    assert got["OMP_NUM_THREADS"] == "1"
    assert os.environ["OPENBLAS_NUM_THREADS"] == "2" and "OMP_NUM_THREADS" not in os.environ


@pytest.mark.parametrize("preset", [None, "3"])
def test_default_sets_only_unset_variables(monkeypatch, preset):
    for v in POOL_VARIABLES:
        monkeypatch.delenv(v, raising=False)
    if preset:
        monkeypatch.setenv("MKL_NUM_THREADS", preset)
    added = default_to_single_threaded_pools()
    assert set(added) == set(POOL_VARIABLES) - ({"MKL_NUM_THREADS"} if preset else set())
    assert os.environ["MKL_NUM_THREADS"] == (preset or "1")
