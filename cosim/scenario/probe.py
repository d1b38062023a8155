"""Import plug-in modules in a child process first, so that one that ends or hangs the interpreter is refused.

Importing a plug-in runs its module's code. A module that calls ``sys.exit`` or ``os._exit`` at import, kills its
process, or never returns would otherwise end or stall ``validate`` and ``run`` with nothing said (exit 0, nothing
run). :func:`probe_imports` imports the modules, in order, in a child process with the caller's ``sys.path``,
while it makes progress (:data:`PLUGIN_IMPORT_IDLE_S`, :data:`PLUGIN_IMPORT_CPU_S`), and returns why each one that did not finish is refused;
the caller then imports the others itself (a module that raises is imported again there and reported with its
exception). Only modules that are not imported yet are probed, so a sweep pays once.

The child is a ``fork`` of this process when it runs a single thread (it has every module this one has: only the
plug-in's own import is paid, a few milliseconds), else a fresh interpreter (a fork of a threaded process may
inherit a lock another thread holds; the fresh interpreter costs its start and the plug-in's dependencies,
~0.1 s with numpy on an idle core). The child reports on a pipe, one line per step (``start``, ``done``,
``exit CODE`` for ``sys.exit``, ``raise``, ``all``); what it does not report (it ended, was killed, timed out)
is read from its exit status.
"""
from __future__ import annotations

import importlib
import json
import os
import select
import signal
import subprocess
import sys
import threading

__all__ = ["PLUGIN_IMPORT_IDLE_S", "PLUGIN_IMPORT_CPU_S", "probe_imports", "can_fork"]

#: longest a plug-in's import may go without progress, s: no CPU time gained and no thread waiting for a core or
#: the disk (it sleeps, or waits for something at import time). Judged by the kernel's evidence
#: (cosim.runtime.liveness.Evidence), not the clock: a first import of a large library on a busy machine takes
#: as long as its share of a core makes it
PLUGIN_IMPORT_IDLE_S = 5.0
#: the CPU time a plug-in's modules may spend importing, s (a loop at import time)
PLUGIN_IMPORT_CPU_S = 60.0
#: how often the probe looks at the importing child, s
_LOOK_S = 0.1

_SPAWNED = """
import importlib, json, os, sys
out = os.fdopen(1, "w", buffering=1)
sys.stdout = open(os.devnull, "w")
sys.path[:] = json.loads(sys.argv[1])
for name in sys.argv[2:]:
    out.write(f"start {name}\\n")
    try:
        importlib.import_module(name)
    except SystemExit as e:
        out.write(f"exit {name} {e.code!r}\\n")
        os._exit(0)
    except BaseException:
        out.write(f"raise {name}\\n")
        os._exit(0)
    out.write(f"done {name}\\n")
out.write("all\\n")
os._exit(0)
"""


def can_fork() -> bool:
    """Whether a fork is a safe probe here: a POSIX system and this process running a single Python thread."""
    return hasattr(os, "fork") and threading.active_count() == 1


def _forked(modules: list[str], path: list[str], write_fd: int) -> None:
    """The forked child: import ``modules``, report each step on ``write_fd``, never return."""
    def say(text: str) -> None:
        os.write(write_fd, (text + "\n").encode())

    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, 1)                             # what a module prints at import is not shown twice
        sys.path[:] = path
        for name in modules:
            say(f"start {name}")
            try:
                importlib.import_module(name)
            except SystemExit as e:
                say(f"exit {name} {e.code!r}")
                return
            except BaseException:       # noqa: BLE001 - reported by the parent's own import, with its exception
                say(f"raise {name}")
                return
            say(f"done {name}")
        say("all")
    finally:
        os._exit(0)


def _start(modules: list[str], path: list[str], fork: bool) -> tuple[int, int, subprocess.Popen | None]:
    """Start one child over ``modules``: (its pid, the read end of its report, the Popen of a fresh interpreter)."""
    if not fork:
        proc = subprocess.Popen([sys.executable, "-c", _SPAWNED, json.dumps(path), *modules], stdin=subprocess.DEVNULL,
                                stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
        return proc.pid, proc.stdout.fileno(), proc
    read_fd, write_fd = os.pipe()
    sys.stdout.flush()
    sys.stderr.flush()
    pid = os.fork()
    if pid == 0:                                        # pragma: no cover - the child reports on the pipe
        os.close(read_fd)
        _forked(modules, path, write_fd)
    os.close(write_fd)
    return pid, read_fd, None


def _run(modules: list[str], path: list[str], fork: bool) -> tuple[str, int | str]:
    """Run one child over ``modules``: (what it reported, its wait status; or why it was killed: "idle" after
    PLUGIN_IMPORT_IDLE_S without progress, "cpu" past PLUGIN_IMPORT_CPU_S of CPU time)."""
    from cosim.runtime.liveness import Evidence

    pid, read_fd, proc = _start(modules, path, fork)
    evidence, report, killed = Evidence(pid), b"", ""
    evidence.idle_s()
    try:
        while True:
            if not select.select([read_fd], [], [], _LOOK_S)[0]:
                killed = "idle" if evidence.idle_s() > PLUGIN_IMPORT_IDLE_S else \
                    "cpu" if evidence.cpu_s > PLUGIN_IMPORT_CPU_S else ""
                if killed:
                    os.kill(pid, signal.SIGKILL)
                    break
                continue
            chunk = os.read(read_fd, 65536)
            if not chunk:                               # the child ended (or closed the pipe)
                break
            report += chunk
    finally:
        if proc is None:
            os.close(read_fd)
    if proc is not None:
        proc.stdout.close()
        code = proc.wait()
        status = (code << 8) if code >= 0 else -code
    else:
        status = os.waitpid(pid, 0)[1]
    return report.decode(errors="replace"), killed or status


def _verdict(report: str, status: int | str, modules: list[str]) -> tuple[dict[str, str], str | None]:
    """(refusals, the module after which the rest was not tried) from a child's report and wait status."""
    started, steps = modules[0], {}
    for line in report.splitlines():
        word, _, rest = line.partition(" ")
        name, _, arg = rest.partition(" ")
        if word == "start":
            started = name
        elif word in ("done", "exit", "raise"):
            steps[name] = (word, arg)
        elif word == "all":
            return {}, None
    step, arg = steps.get(started, ("", ""))
    if step == "raise":
        return {}, started                              # this process's own import reports the exception
    if step == "exit":
        return {started: f"importing module {started!r} calls sys.exit({arg}); a plug-in module must only define "
                         "things when imported"}, started
    if status == "idle":
        return {started: f"importing module {started!r} made no progress for {PLUGIN_IMPORT_IDLE_S:g} s: no CPU "
                         "time, no thread waiting for a core or the disk (it sleeps, or waits for something at "
                         "import time)"}, started
    if status == "cpu":
        return {started: f"importing module {started!r} did not finish within {PLUGIN_IMPORT_CPU_S:g} s of CPU "
                         "time (a loop at import time?)"}, started
    if os.WIFSIGNALED(status):
        try:
            sig = signal.Signals(os.WTERMSIG(status)).name
        except ValueError:
            sig = f"signal {os.WTERMSIG(status)}"
        return {started: f"importing module {started!r} kills the interpreter ({sig})"}, started
    return {started: f"importing module {started!r} ends the interpreter (os._exit at import time, exit status "
                     f"{os.waitstatus_to_exitcode(status)}); a plug-in module must only define things when "
                     "imported"}, started


def probe_imports(modules: list[str], path: list[str] | None = None, fork: bool | None = None) -> dict[str, str]:
    """Module name -> why it is refused, for each of ``modules`` whose import ends the interpreter, kills it,
    makes no progress for :data:`PLUGIN_IMPORT_IDLE_S` or spends more than :data:`PLUGIN_IMPORT_CPU_S` of CPU
    time; ``path``: the ``sys.path`` to import with (default: this process's); ``fork``: probe in a fork (default:
    :func:`can_fork`) or a fresh interpreter. A module whose import raises is not in the result."""
    modules = [m for m in dict.fromkeys(modules) if m not in sys.modules]
    path = list(sys.path if path is None else path)
    fork = can_fork() if fork is None else fork
    refused: dict[str, str] = {}
    while modules:
        report, status = _run(modules, path, fork)
        bad, stop = _verdict(report, status, modules)
        refused.update(bad)
        if stop is None:
            break
        modules = modules[modules.index(stop) + 1:]    # the rest were not tried: probe them too
    return refused
