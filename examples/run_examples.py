"""Run every example briefly (CI: .ci/run); exit 1 naming each example that failed.

For every folder under ``examples/`` (or the ``--root`` given), in name order:

1. ``build.py``, if there is one (``python <folder>/build.py``: builds what the example needs, such as an FMU);
2. ``python launch.py run <folder>/scenario.yaml --duration 3 --quiet --out <tmp>/<folder>``, if there is a
   scenario, with ``--renderer none`` for a ground-truth scenario and ``--renderer mock`` otherwise (no OpenGL
   needed); a README can ask for more options than these (``RUN_OPTIONS`` below);
3. every other ``*.py`` that is a script (it has an ``if __name__ == "__main__":`` guard or ``# %%`` cells; plug-in
   modules have neither), with ``GRAINCOSIM_EXAMPLE_QUICK=1`` (make it short) and ``GRAINCOSIM_EXAMPLE_OUT=<tmp>/
   <folder>`` (where to write).

Every command runs from the repository root with the repository first on ``PYTHONPATH``.

    python examples/run_examples.py                  # all
    python examples/run_examples.py notebook_api     # some
"""
from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
#: simulated seconds of each example scenario's run
DURATION_S = 3.0
#: wall-clock limit of one command, s
TIMEOUT_S = 600.0
#: lines of a failed command's output shown
TAIL_LINES = 30
#: a script: a main guard or notebook cells
SCRIPT_MARK = re.compile(r'^(if __name__ == ["\']__main__["\']:|# %%)', re.MULTILINE)


def renderer_for(scenario: Path) -> str:
    """``none`` for a scenario with ground-truth feedback (nothing needs images), else ``mock``; ``mock`` when the
    scenario does not load (``launch.py`` then reports why)."""
    sys.path.insert(0, str(REPO))
    try:
        from cosim.scenario.loader import load_scenario

        return "none" if load_scenario(scenario).feedback == "ground_truth" else "mock"
    except Exception:  # noqa: BLE001 - the run itself names the problem
        return "mock"
    finally:
        sys.path.remove(str(REPO))


def scripts(folder: Path) -> list[Path]:
    """The folder's scripts: ``*.py`` but build.py, with a main guard or ``# %%`` cells."""
    return [p for p in sorted(folder.glob("*.py")) if p.name != "build.py"
            and SCRIPT_MARK.search(p.read_text(encoding="utf-8"))]


def commands(folder: Path, out: Path) -> list[tuple[str, list[str], dict]]:
    """(label, argv, extra environment) of each command the example ``folder`` runs, in order."""
    py = sys.executable
    cmds = []
    if (folder / "build.py").is_file():
        cmds.append(("build.py", [py, str(folder / "build.py")], {}))
    scenario = folder / "scenario.yaml"
    if scenario.is_file():
        cmds.append(("scenario.yaml", [py, "launch.py", "run", str(scenario), "--duration", f"{DURATION_S:g}",
                                       "--renderer", renderer_for(scenario), "--quiet", "--out",
                                       str(out / "run"), "--parents", "--overwrite"], {}))
    env = {"GRAINCOSIM_EXAMPLE_QUICK": "1", "GRAINCOSIM_EXAMPLE_OUT": str(out)}
    cmds += [(p.name, [py, str(p)], env) for p in scripts(folder)]
    return cmds


def run_example(folder: Path, out: Path) -> list[str]:
    """Run one example; return the failures (label: reason), empty when it passed."""
    failures = []
    for label, argv, extra in commands(folder, out):
        env = {**os.environ, **extra, "PYTHONPATH": os.pathsep.join(
            [str(REPO), *filter(None, [os.environ.get("PYTHONPATH")])])}
        t0 = time.perf_counter()
        try:
            p = subprocess.run(argv, cwd=REPO, env=env, capture_output=True, text=True, timeout=TIMEOUT_S)
            ok, why, output = p.returncode == 0, f"exit status {p.returncode}", p.stdout + p.stderr
        except subprocess.TimeoutExpired as e:
            ok, why = False, f"timed out after {TIMEOUT_S:g} s"
            output = (e.stdout or b"").decode(errors="replace") + (e.stderr or b"").decode(errors="replace")
        print(f"  {label}: {'ok' if ok else 'FAILED (' + why + ')'} in {time.perf_counter() - t0:.1f} s",
              flush=True)
        if not ok:
            tail = "\n".join(output.splitlines()[-TAIL_LINES:])
            print("    " + tail.replace("\n", "\n    "), flush=True)
            failures.append(f"{label}: {why}")
            break
    return failures


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("names", nargs="*", help="example folders to run (default: all)")
    ap.add_argument("--root", type=Path, default=Path(__file__).resolve().parent, help="examples folder")
    ap.add_argument("--out", type=Path, help="where the examples write (default: a temporary folder)")
    args = ap.parse_args(argv)
    folders = sorted(p for p in args.root.iterdir() if p.is_dir() and not p.name.startswith((".", "_")))
    if args.names:
        unknown = sorted(set(args.names) - {p.name for p in folders})
        if unknown:
            print(f"no example {', '.join(unknown)} in {args.root}", file=sys.stderr)
            return 2
        folders = [p for p in folders if p.name in args.names]
    failed: dict[str, list[str]] = {}
    with tempfile.TemporaryDirectory(prefix="cosim-examples-") as tmp:
        out_root = args.out or Path(tmp)
        for folder in folders:
            print(f"{folder.name}:", flush=True)
            if not commands(folder, out_root / folder.name):
                print("  nothing to run (no build.py, scenario.yaml or script)")
                continue
            problems = run_example(folder, out_root / folder.name)
            if problems:
                failed[folder.name] = problems
    if failed:
        print("FAILED examples: " + "; ".join(f"{n} ({', '.join(p)})" for n, p in failed.items()), file=sys.stderr)
        return 1
    print(f"{len(folders)} example(s) passed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
