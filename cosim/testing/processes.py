"""Which processes a launcher has started, for the runtime tests' "nothing left behind" checks."""
from __future__ import annotations

import subprocess

__all__ = ["ring_children"]


def _children(pid: int) -> list[tuple[int, str]]:
    out = subprocess.run(["ps", "-ww", "-o", "pid=,args=", "--ppid", str(pid)], capture_output=True, text=True).stdout
    return [(int(line.split(None, 1)[0]), line.split(None, 1)[1] if " " in line.strip() else "")
            for line in out.splitlines() if line.strip()]


def ring_children(pid: int) -> list[int]:
    """The worker processes of launcher ``pid``: its spawned children and the children of its fork server
    (cosim.runtime.procstart), not its resource tracker or the fork server itself."""
    out = []
    for child, args in _children(pid):
        if "multiprocessing.spawn" in args:
            out.append(child)
        elif "multiprocessing.forkserver" in args:
            out.extend(c for c, _ in _children(child))
    return out
