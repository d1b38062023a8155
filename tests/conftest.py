"""Shared fixtures. ``tests/`` is put on sys.path so spawned children can import test-only modules (sweep runners,
plug-ins written by a test); the stand-in participants live in cosim/testing/fakes.py."""
from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parent
if str(TESTS) not in sys.path:
    sys.path.insert(0, str(TESTS))

SHM = Path("/dev/shm")


def segments(pid: int | None = None) -> set[str]:
    """Names of the project's segments in /dev/shm made by launcher ``pid`` (default: this process)."""
    pid = os.getpid() if pid is None else pid
    if not SHM.exists():
        return set()
    return {p.name for p in SHM.iterdir() if p.name.startswith((f"cosim-{pid}-", f"cosimtest-{pid}-"))}


def _ours() -> set[str]:
    return segments()


@pytest.fixture
def shm_clean():
    """Fails the test if it leaves a project segment in /dev/shm."""
    before = _ours()
    yield
    left = _ours() - before
    assert not left, f"segments left in /dev/shm: {sorted(left)}"


@pytest.fixture
def shm_name(request):
    """A unique segment name for one test."""
    return f"cosimtest-{os.getpid()}-{abs(hash(request.node.nodeid)) % 10**8}"


@pytest.fixture(scope="session")
def built_fmus(tmp_path_factory):
    """The test FMUs (tests/fmu_builds.py), built once per session with pythonfmu: name -> .fmu path."""
    import fmu_builds

    if fmu_builds.MISSING:
        pytest.skip(f"FMU tests need {' and '.join(fmu_builds.MISSING)} (pip install -e \".[test]\")")
    return fmu_builds.build_all(tmp_path_factory.mktemp("fmus"))


@pytest.fixture(scope="module")
def ctx():
    """A headless GL context (EGL) for a test module; the module is skipped with the reason where none can be made."""
    from cosim.errors import RendererUnavailable
    from renderer_proc.gl.backend import create_gl_context

    try:
        c = create_gl_context()
    except RendererUnavailable as exc:
        pytest.skip(str(exc))
    yield c
    c.release()


@pytest.fixture(scope="module")
def cpu_gl(ctx) -> bool:
    """Whether ``ctx`` is a CPU rasteriser (llvmpipe, softpipe, swr): IEEE float32 arithmetic and interpolation,
    where the GL tests hold bits. A GPU's hardware interpolation and approximate division hold to a tolerance
    instead (each test says which)."""
    from renderer_proc.gl.beam import cpu_rasteriser

    return cpu_rasteriser(ctx.info["GL_RENDERER"])
