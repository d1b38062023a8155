"""A busy machine on demand: N processes that each spin one core, beside a test, a bench case or a command.

This is what a user's laptop with a browser open, or a shared CI runner, does to a run: every process of the run
gets a fraction of a core. The liveness rules (cosim.runtime.liveness) must wait for such a run and still name a
real hang; the tests and the ``underload`` bench case use :func:`busy`, and the command line runs anything under
load::

    python -m cosim.testing.load 10 -- python -m pytest        # the suite beside 10 busy processes
    python -m cosim.testing.load 10 -- python launch.py run default --duration 10

The busy processes are plain ``python3 -c 'while True: pass'`` loops at the caller's priority, started in their
own process group and ended (SIGKILL) when the block or the command ends, whatever happens.
"""
from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
from typing import Iterator, Sequence

__all__ = ["busy", "load_average", "loaded", "promised", "main"]

#: the loop each busy process runs
SPIN = "while True: pass"


@contextlib.contextmanager
def busy(n: int) -> Iterator[list[int]]:
    """Run ``n`` busy processes for the duration of the block; yields their pids."""
    procs = [subprocess.Popen([sys.executable, "-c", SPIN], stdin=subprocess.DEVNULL, start_new_session=True)
             for _ in range(max(0, n))]
    try:
        yield [p.pid for p in procs]
    finally:
        for p in procs:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(p.pid, signal.SIGKILL)
        for p in procs:
            p.wait()


def load_average() -> float:
    """The machine's one-minute load average (0.0 where it cannot be read)."""
    try:
        return os.getloadavg()[0]
    except OSError:
        return 0.0


def loaded() -> bool:
    """Whether the machine is busy: more runnable work than cores over the last minute."""
    return load_average() > (os.cpu_count() or 1)


def promised(quiet_s: float, loaded_s: float | None = None) -> float:
    """The bound a timing promise holds to on this machine now: ``quiet_s`` on a quiet machine, ``loaded_s``
    (default three times as long) on a busy one (:func:`loaded`). The liveness promises are 2 s quiet and 6 s at
    a load of 12 on 2 cores (docs/reliability.md); tests of them use this, so that the suite passes where users
    run it."""
    return (3.0 * quiet_s if loaded_s is None else loaded_s) if loaded() else quiet_s


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m cosim.testing.load N -- COMMAND...``: run COMMAND beside N busy processes; its exit status."""
    args = list(sys.argv[1:] if argv is None else argv)
    if len(args) < 3 or args[1] != "--" or not args[0].isdigit():
        print("usage: python -m cosim.testing.load N -- COMMAND [ARGS...]", file=sys.stderr)
        return 2
    with busy(int(args[0])):
        try:
            return subprocess.call(args[2:])
        except KeyboardInterrupt:
            return 130


if __name__ == "__main__":
    sys.exit(main())
