"""The machine a measurement ran on and how busy it was: cores, CPU model, memory, Python and numpy, the load
average, the date, and the commit of each source tree measured."""
from __future__ import annotations

import os
import platform
import subprocess
from datetime import datetime, timezone
from pathlib import Path

__all__ = ["commit", "describe", "facts", "load", "now_utc"]


def load() -> float:
    """The 1-minute load average (runnable processes; compare with the core count)."""
    return os.getloadavg()[0]


def now_utc() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="seconds")


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _memory_gib() -> float | None:
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal:"):
                return int(line.split()[1]) / 2**20
    except OSError:
        pass
    return None


def facts() -> dict:
    """What a reader needs to compare a figure with their own: cores, CPU model, memory (GiB), Python, numpy,
    the operating system."""
    try:
        import numpy

        numpy_version = numpy.__version__
    except ImportError:
        numpy_version = None
    return {"cores": os.cpu_count(), "cpu": _cpu_model(), "memory_gib": _memory_gib(),
            "python": platform.python_version(), "numpy": numpy_version,
            "system": f"{platform.system()} {platform.release()}"}


def describe(f: dict) -> str:
    """One line of :func:`facts` for a report."""
    mem = f"{f['memory_gib']:.0f} GiB, " if f.get("memory_gib") else ""
    return f"{f['cores']} cores ({f['cpu']}), {mem}Python {f['python']}, numpy {f['numpy']}, {f['system']}"


def commit(tree: str | os.PathLike) -> str | None:
    """Short commit of the git checkout ``tree`` with ``+changes`` where tracked files differ from it; None where
    it is not a git checkout."""
    def git(*args: str) -> str:
        return subprocess.run(["git", *args], cwd=tree, capture_output=True, text=True, check=True).stdout.strip()

    try:
        head = git("rev-parse", "--short=10", "HEAD")
        return head + ("+changes" if git("status", "--porcelain", "--untracked-files=no") else "")
    except (OSError, subprocess.CalledProcessError):
        return None
