"""Import plug-in modules in a child process first, so that one that ends or hangs the interpreter is refused.

Importing a plug-in runs its module's code. A module that calls ``sys.exit`` or ``os._exit`` at import, kills its
process, or never returns would otherwise end or stall ``validate`` and ``run`` with nothing said (exit 0, nothing
run). :func:`probe_imports` imports the modules, in order, in one child interpreter with the caller's
``sys.path``, under a time limit (:data:`PLUGIN_IMPORT_TIMEOUT_S`), and returns why each one that did not finish
is refused; the caller then imports the others itself (a module that raises is imported again there and reported
with its exception). Only modules that are not imported yet are probed, so a sweep pays once.

Cost: one interpreter start plus the modules' own import time, only for scenarios that name a plug-in that is not
built in (the packaged scenarios name none); docs/plugins.md gives the measured figure.
"""
from __future__ import annotations

import json
import secrets
import signal
import subprocess
import sys

__all__ = ["PLUGIN_IMPORT_TIMEOUT_S", "probe_imports"]

#: longest a plug-in's modules may take to import, s (a first import of a large library takes seconds)
PLUGIN_IMPORT_TIMEOUT_S = 30.0

#: the child: imports each module, announcing it on stdout (lines tagged with a nonce, so that what a module
#: prints is not taken for the protocol)
_CHILD = """
import importlib, json, sys
tag = sys.argv[1]
sys.path[:] = json.loads(sys.argv[2])
for name in sys.argv[3:]:
    print(tag, "start", name, flush=True)
    importlib.import_module(name)
    print(tag, "done", name, flush=True)
print(tag, "all", flush=True)
"""


def _protocol(stdout: str, tag: str) -> tuple[str | None, bool]:
    """(the module whose import began but did not finish, whether every import finished)."""
    started, done, finished = None, set(), False
    for line in stdout.splitlines():
        parts = line.split(" ", 2)
        if len(parts) >= 2 and parts[0] == tag:
            if parts[1] == "start":
                started = parts[2]
            elif parts[1] == "done":
                done.add(parts[2])
            elif parts[1] == "all":
                finished = True
    return (started if started is not None and started not in done else None), finished


def _probe(modules: list[str], path: list[str], limit: float) -> tuple[dict[str, str], str | None]:
    """One child importing ``modules``: (refusals, the module that raised, after which the rest was not tried)."""
    tag = secrets.token_hex(8)
    argv = [sys.executable, "-c", _CHILD, tag, json.dumps(path), *modules]
    try:
        done = subprocess.run(argv, stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=limit)
    except subprocess.TimeoutExpired as e:
        out = e.stdout.decode(errors="replace") if isinstance(e.stdout, bytes) else (e.stdout or "")
        name = _protocol(out, tag)[0] or modules[0]
        return {name: f"importing module {name!r} did not finish within {limit:g} s (it hangs, or waits for "
                      "something at import time)"}, None
    name, finished = _protocol(done.stdout, tag)
    if finished:
        return {}, None
    name = name or modules[0]
    if done.returncode < 0:
        try:
            sig = signal.Signals(-done.returncode).name
        except ValueError:
            sig = f"signal {-done.returncode}"
        return {name: f"importing module {name!r} kills the interpreter ({sig})"}, None
    if "Traceback (most recent call last)" in done.stderr:
        return {}, name                             # it raises: the import in this process reports the exception
    return {name: f"importing module {name!r} ends the interpreter (sys.exit or os._exit at import time, exit "
                  f"status {done.returncode}); a plug-in module must only define things when imported"}, None


def probe_imports(modules: list[str], path: list[str] | None = None,
                  timeout_s: float | None = None) -> dict[str, str]:
    """Module name -> why it is refused, for each of ``modules`` whose import ends the interpreter, kills it or
    does not finish within ``timeout_s`` (default :data:`PLUGIN_IMPORT_TIMEOUT_S`); ``path``: the ``sys.path``
    to import with (default: this process's). A module whose import raises is not in the result."""
    modules = [m for m in dict.fromkeys(modules) if m not in sys.modules]
    if not modules:
        return {}
    limit = PLUGIN_IMPORT_TIMEOUT_S if timeout_s is None else timeout_s
    path = list(sys.path if path is None else path)
    refused: dict[str, str] = {}
    while modules:
        bad, raised = _probe(modules, path, limit)
        refused.update(bad)
        stop = raised or next(iter(bad), None)
        if stop is None:
            break
        modules = modules[modules.index(stop) + 1:]    # the rest were not tried: probe them too
    return refused
