"""Instruction counts under ``valgrind --tool=callgrind``: deterministic where timings on a shared machine are not.

* :func:`instructions` runs a command under callgrind (optionally collecting only inside one C function, e.g.
  ``functools_reduce`` around a measured loop) and returns its instruction count;
* :class:`ClientRequests` toggles collection and dumps named counts from inside the measured Python process (a
  small library compiled on first use into ``bench/out``), and :func:`dump_totals` sums the named dumps.

Run the interpreter itself under valgrind (``sys.executable``), not a shell shim: valgrind does not follow children.
Callgrind counts each iteration of ``rep movsb``/``rep stosb`` as an instruction, so a large memcpy or memset weighs
about one instruction per byte, far more than in time. PYTHONHASHSEED is fixed so that counts repeat.
"""
from __future__ import annotations

import ctypes
import os
import re
import subprocess
import sys
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator, Mapping, Sequence

__all__ = ["ClientRequests", "available", "dump_totals", "instructions", "total"]

#: the client-request library's source (valgrind/callgrind.h macros as functions)
_SOURCE = """#include <valgrind/callgrind.h>
void cg_toggle(void) { CALLGRIND_TOGGLE_COLLECT; }
void cg_dump(const char *name) { CALLGRIND_DUMP_STATS_AT(name); }
void cg_zero(void) { CALLGRIND_ZERO_STATS; }
"""
_LIB = Path(__file__).resolve().parents[1] / "out" / "cgreq.so"
_TOTAL = re.compile(r"^(?:summary|totals): (\d+)", re.M)


def available() -> bool:
    """Whether valgrind can be run."""
    try:
        return subprocess.run(["valgrind", "--version"], capture_output=True).returncode == 0
    except OSError:
        return False


def total(path: Path) -> int:
    """Instructions (Ir) in one callgrind output file."""
    return int(_TOTAL.search(path.read_text(errors="replace")).group(1))


def instructions(args: Sequence[str], cwd: Path, env: Mapping[str, str] | None = None, toggle: str | None = None,
                 warm: bool = True, options: Sequence[str] = ()) -> int:
    """Instructions of ``python ARGS`` (run in ``cwd``) under callgrind; ``toggle``: collect only inside that C
    function; ``warm``: run it natively first, so that every module's bytecode is cached; ``options``: more
    callgrind options (e.g. ``--collect-atstart=no`` where the program toggles collection itself)."""
    env = {**(env or os.environ), "PYTHONHASHSEED": "0"}
    if warm:
        subprocess.run([sys.executable, *args], cwd=cwd, env=env, check=True, stdout=subprocess.DEVNULL)
    with tempfile.TemporaryDirectory(prefix="bench-cg-") as tmp:
        out = Path(tmp) / "callgrind.out"
        extra = [f"--toggle-collect={toggle}"] if toggle else []
        extra += list(options)
        subprocess.run(["valgrind", "--tool=callgrind", *extra, f"--callgrind-out-file={out}", sys.executable, *args],
                       cwd=cwd, env=env, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        return total(out)


def dump_totals(paths: Sequence[Path]) -> dict[str, int]:
    """Instructions per dump name (``CALLGRIND_DUMP_STATS_AT``'s argument), summed over the output files."""
    out: dict[str, int] = {}
    for p in paths:
        text = p.read_text(errors="replace")
        name = re.search(r"^desc: Trigger: Client Request: (.*)$", text, re.M)
        m = _TOTAL.search(text)
        if name and m:
            key = name.group(1).strip()
            out[key] = out.get(key, 0) + int(m.group(1))
    return out


class ClientRequests:
    """Callgrind client requests from Python: :meth:`collect` counts a block and dumps it under a name;
    :meth:`exclude` leaves a part of such a block out. Outside valgrind the requests do nothing."""

    active = False

    def __init__(self):
        if not _LIB.exists():
            src = _LIB.with_suffix(".c")
            _LIB.parent.mkdir(parents=True, exist_ok=True)
            src.write_text(_SOURCE)
            subprocess.run(["cc", "-O1", "-shared", "-fPIC", "-o", str(_LIB), str(src)], check=True)
        self.lib = ctypes.CDLL(str(_LIB))

    @contextmanager
    def collect(self, name: str) -> Iterator[None]:
        self.lib.cg_zero()
        self.lib.cg_toggle()
        self.active = True
        try:
            yield
        finally:
            self.active = False
            self.lib.cg_toggle()
            self.lib.cg_dump(name.encode())

    @contextmanager
    def exclude(self) -> Iterator[None]:
        """Not collected (inside :meth:`collect`; nothing outside)."""
        if not self.active:
            yield
            return
        self.lib.cg_toggle()
        try:
            yield
        finally:
            self.lib.cg_toggle()
