"""What a process's threads are doing, from /proc: the report attached to a member named hung.

One line per thread (Linux; an empty report elsewhere or once the process is gone)::

    tid 4242 MainThread S cpu 1.234 s, run-queue wait 0.567 s, 120 slices, switches 80 voluntary / 40 forced, in futex_wait_queue

* ``cpu`` and ``run-queue wait``: ``/proc/<pid>/task/<tid>/schedstat`` (time on a core, time runnable but waiting
  for one), s;
* ``switches``: ``voluntary_ctxt_switches`` (it slept) and ``nonvoluntary_ctxt_switches`` (it was preempted) from
  ``status``;
* ``in``: the kernel function it sleeps in (``wchan``; "-" when running or hidden).

A starved thread gains run-queue wait and forced switches; a deadlocked one sleeps in one place and gains neither.
"""
from __future__ import annotations

import os

__all__ = ["thread_report", "read_proc", "stat_fields"]


def read_proc(path: str) -> bytes:
    """The bytes of a /proc file (raises OSError when it cannot be read: the process or thread is gone)."""
    with open(path, "rb") as f:
        return f.read()


def stat_fields(raw: bytes) -> list[bytes]:
    """The fields of a /proc stat line after ``comm`` (which may hold spaces and parentheses): state first."""
    return raw[raw.rfind(b")") + 2:].split()


def _text(path: str) -> str:
    return read_proc(path).decode("utf-8", "replace").strip()


def _switches(status: str) -> tuple[str, str]:
    found = {}
    for line in status.splitlines():
        key, _, value = line.partition(":")
        if key in ("voluntary_ctxt_switches", "nonvoluntary_ctxt_switches"):
            found[key] = value.strip()
    return found.get("voluntary_ctxt_switches", "?"), found.get("nonvoluntary_ctxt_switches", "?")


def _line(pid: int, tid: str) -> str:
    base = f"/proc/{pid}/task/{tid}/"
    state = stat_fields(read_proc(base + "stat"))[0].decode("ascii", "replace")
    name = _text(base + "comm")
    try:
        cpu_ns, wait_ns, slices = (int(x) for x in _text(base + "schedstat").split()[:3])
        times = f"cpu {cpu_ns / 1e9:.3f} s, run-queue wait {wait_ns / 1e9:.3f} s, {slices} slices"
    except (OSError, ValueError):
        times = "cpu ? (no schedstat)"
    voluntary, forced = _switches(_text(base + "status"))
    try:
        wchan = _text(base + "wchan") or "-"
    except OSError:
        wchan = "-"
    wchan = "-" if wchan == "0" else wchan
    return f"tid {tid} {name} {state} {times}, switches {voluntary} voluntary / {forced} forced, in {wchan}"


def thread_report(pid: int) -> list[str]:
    """One line per thread of ``pid`` (module docstring); [] when it cannot be read."""
    try:
        tids = sorted(os.listdir(f"/proc/{pid}/task"), key=int)
    except OSError:
        return []
    lines = []
    for tid in tids:
        try:
            lines.append(_line(pid, tid))
        except (OSError, IndexError, ValueError):  # a thread that ended meanwhile
            continue
    return lines
